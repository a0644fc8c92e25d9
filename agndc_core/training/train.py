"""Training the AGNDC cascade (paper Sec. 3.3): each scale's AGDRNet on its own, coarse to fine.

Scale ``levels`` (AGDRNet*) is trained first on its own labels; then each finer scale s is trained
with the already-trained coarser networks frozen, fed with their prediction P_{s+1} on the same
crop, exactly as at inference. The UNDC baseline (``levels = 0``) is the same loop with one scale.

Everything a run needs is in ``TrainConfig``; a run directory holds ``run.json`` (config + log),
``state.safetensors`` (model, optimiser and loss weights, for ``--resume``; no pickle) and
``final.safetensors``/``final.json``, the self-describing checkpoint (``checkpoint.py``). Steps are
seeded by (seed, scale, step), so a resumed run draws the same crops as an uninterrupted one.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from ..errors import AGNDCError
from ..labels import binary_visible_vertex
from ..nn.config import ABLATION_KEYS
from ..nn.loss import QUADRIC_FLOOR
from ..surfacenets import surface_nets_lattice
from .crops import SparseSample, make_crop, random_crop_origin, valid_cells
from .data import load_sample

log = logging.getLogger(__name__)

#: largest file the trainer writes (state shards included): under the 16 MiB a file returned from
#: the GPU machine of the runbook may have (docs/training.md)
MAX_FILE_BYTES = 15 * 2**20
#: ``TrainConfig.compile`` modes and their torch.compile arguments
COMPILE_MODES = {"inductor": {}, "reduce-overhead": {"mode": "reduce-overhead"},
                 "cudagraphs": {"backend": "cudagraphs"}, "aot_eager": {"backend": "aot_eager"}}


@dataclass
class TrainConfig:
    data: str  # folder(s) of samples written by data.build_dataset (comma-separated)
    out: str  # run directory
    val: str | None = None  # folder of held-out samples (CD/F1 after the finest scale)
    model: dict = field(default_factory=dict)  # AGNDCConfig fields
    steps: list = field(default_factory=lambda: [1000, 500, 500])  # per scale s = 0..levels
    batch: int = 4
    crop: list = field(default_factory=lambda: [32, 24, 32])  # crop edge per scale s (clipped)
    # cells this close to a crop border that lies inside the lattice are not scored: the
    # network replicate-pads there, so their context is invented (per scale s)
    margin: list = field(default_factory=lambda: [6, 4, 2])
    lr: float = 2e-3
    warmup: int = 50
    seed: int = 0
    threads: int = 2
    log_every: int = 25
    save_every: int = 100
    val_count: int = 8
    val_samples: int = 20_000  # surface samples per mesh for the validation metrics
    device: str = "cpu"  # "cpu", "cuda", "cuda:1", ...
    amp: bool = True  # bf16 autocast on CUDA (ignored on the CPU)
    workers: int = 0  # data-loader worker processes building crops (0: in the main process)
    # torch.compile the trained scale's forward + loss and the frozen coarser scales' forward:
    # "" (eager), "inductor", "reduce-overhead" (inductor + CUDA graphs), "cudagraphs" (CUDA
    # graphs of the eager kernels, no code generation) or "aot_eager" (traced, eager kernels:
    # a CPU check of the trace). A width-16 step on a GPU is bound by launching hundreds of small
    # kernels (docs/experiments/step-times.md); CUDA graphs launch them as one. Not saved with
    # the weights: a run may be resumed with another mode
    compile: str = ""
    # warm start: a checkpoint (.safetensors) of the same architecture whose weights start the
    # run; if it predicted absolute offsets (no surface nets prior), its finest last vertex
    # layer restarts at zero so the run starts exactly at surface nets
    init: str | None = None
    # the ``init`` checkpoint may differ from the model in the ablation switches (ABLATION_KEYS):
    # every tensor whose name and shape agree is loaded, the rest start fresh. Starts an
    # ablation of Table 4 from the trained full model (docs/experiments/table4-ablation.md); off
    # by default, so a mistyped --model never silently drops half a warm start
    init_matching: bool = False
    # steps of the finest scale after which a checkpoint ``step-NNNNNN`` of the (averaged)
    # weights is written and the held-out samples are scored: the points of a learning curve
    val_steps: list = field(default_factory=list)
    # stop cleanly (state saved, ``--resume`` continues) once this much wall time has passed:
    # a command on the runbook's GPU machine is limited to 10 minutes; None = no limit
    max_seconds: float | None = None
    # weight of the plain squared vertex error beside the normal quadric (nn.loss): small lets a
    # vertex slide along its face, 1 pins it to the labelled (QEF) vertex as plain MSE does
    quadric_floor: float = QUADRIC_FLOOR
    # extra weight of crease and corner cells in the vertex loss (nn.loss: a cell whose normal
    # quadric has two strong directions counts 1 + crease_weight); 0 = every surface cell alike
    crease_weight: float = 0.0
    # exponential moving average of the trained scale's weights (decay per step; 0 = off). A
    # batch of 4 crops makes every step noisy; the average is what validation scores and what
    # the checkpoint keeps, and it is committed to the scale before finer scales train on it
    ema: float = 0.0
    # crops may reach past the lattice's ends (``crops.random_crop_origin``): the empty space
    # in front of a face is no longer always the same 2 points
    outside_crops: bool = False
    # crops may start at any point of their scale instead of on a window boundary: the part then
    # meets the coarse scales' pooling and the attention windows at every phase, as a surface
    # anywhere in a user's grid does (aligned crops show a part's low faces at one phase only).
    # Off by default: measured worse on the dev meshes (docs/experiments/frame-phase.md, cpu2).
    # Why is open: the guess that it hides a cue of voxelize's frame was measured and rejected
    # (gpu1 keeps its lead on shifted grids)
    random_phase: bool = False
    # on cells of exactly axis-aligned faces the finest scale's target coordinate along the
    # normal is the layer's midpoint (``labels.binary_visible_vertex``, the ``oracle_binary``
    # vertex), not the true depth: every depth in the layer leaves the same voxels there, so
    # the true one is mostly noise to the network. Measured
    # (docs/experiments/binary-targets-curriculum.md): from scratch better on all five dev
    # metrics at equal steps; continuing a trained network with it loses CD, since a face's
    # neighbours can pin its depth and this forbids learning that. Off by default
    binary_targets: bool = False


class Trainer:
    def __init__(self, cfg: TrainConfig):
        from ..nn import AGNDCCascade, AGNDCConfig, AGNDCLoss

        self.cfg = cfg
        self.out = Path(cfg.out)
        self.model_config = AGNDCConfig.from_dict(cfg.model) if cfg.model else AGNDCConfig()
        levels = self.model_config.levels
        if len(cfg.steps) != levels + 1:
            raise AGNDCError(f"--steps needs {levels + 1} values (scales 0..{levels}), "
                             f"got {cfg.steps}")
        torch.manual_seed(cfg.seed)
        torch.set_num_threads(cfg.threads)
        self.device = torch.device(cfg.device)
        if cfg.compile and cfg.compile not in COMPILE_MODES:
            raise AGNDCError(f"--compile {cfg.compile!r}: one of {', '.join(COMPILE_MODES)}")
        if self.device.type == "cuda" and not torch.cuda.is_available():
            raise AGNDCError(f"--device {cfg.device}: this torch build sees no CUDA device")
        self.model = AGNDCCascade(self.model_config).to(self.device)
        # the finest scale's edges are the input's crossing parity (inference always contours
        # the input's topology): no edge loss there, its gradient would train a dead head
        self.losses = torch.nn.ModuleList([
            AGNDCLoss(train_edges=s != 0, quadric_floor=cfg.quadric_floor,
                      crease_weight=cfg.crease_weight)
            for s in range(levels + 1)]).to(self.device)
        # what an --init-matching warm start loaded (None: a whole checkpoint, or none)
        self.warm_start: dict | None = None
        # the training record of the --init checkpoint: the lineage these weights continue
        self.init_training: dict | None = None
        if cfg.init:
            self._warm_start(cfg.init)
        self.samples = _load_folder(cfg.data, levels, cfg.workers)
        self.log: list[dict] = []
        # each process that ran steps of this run: its hardware and where it began (a run
        # resumed on another machine, e.g. started on the CPU and finished on a GPU)
        self.sessions: list[dict] = []
        self.scale, self.step = levels, 0  # next step to run
        self.optimizer = self._optimizer(self.scale)
        self.ema = self._start_ema(self.scale)
        self.seconds = 0.0
        # of which waiting for the next batch: how much of a step the crop builders set
        self.data_seconds = 0.0
        self._compiled_fns: dict = {}  # (role, scale) -> compiled function (cfg.compile)
        self._compiled_scales: set = set()  # scales whose compiled step has run once

    def _warm_start(self, path: str) -> None:
        from ..checkpoint import load_checkpoint

        source, meta = load_checkpoint(path)
        self.init_training = meta.get("training") or {}
        mine, theirs = self.model_config.to_dict(), source.config.to_dict()
        differ = sorted(k for k in mine if k not in ("surface_nets_prior", "band_radius")
                        and mine[k] != theirs.get(k))
        ablation = set(differ) <= set(ABLATION_KEYS)
        if differ and not (ablation and self.cfg.init_matching):
            hint = (" (switches of an ablation: --init-matching loads the tensors the two "
                    "share)" if ablation else "")
            raise AGNDCError(f"--init {path}: its architecture differs in "
                             f"{', '.join(differ)}{hint}")
        if differ:
            self.warm_start = _load_matching(self.model, source.state_dict())
            self.warm_start["checkpoint"] = str(path)
            log.info("warm start from %s: %d tensors loaded; fresh: %s; dropped: %s", path,
                     self.warm_start["loaded"], ", ".join(self.warm_start["fresh"]) or "none",
                     ", ".join(self.warm_start["dropped"]) or "none")
        else:
            self.model.load_state_dict(source.state_dict())
        if self.model_config.surface_nets_prior and not source.config.surface_nets_prior:
            self.model._init_outputs(self.model.nets[0], snakes=False)

    # ------------------------------------------------------------------ schedule
    def begin_scale(self, s: int) -> None:
        """Train scale s from its first step: a fresh optimiser and weight average for its net."""
        self.scale, self.step = s, 0
        self.optimizer = self._optimizer(s)
        self.ema = self._start_ema(s)

    def _optimizer(self, s: int):
        params = list(self.model.nets[s].parameters()) + list(self.losses[s].parameters())
        return torch.optim.AdamW(params, lr=self.cfg.lr, weight_decay=1e-4)

    def _start_ema(self, s: int) -> dict | None:
        """Averaged copies of scale s's parameters (None when ``cfg.ema`` is 0)."""
        if not self.cfg.ema:
            return None
        return {k: p.detach().clone() for k, p in self.model.nets[s].named_parameters()}

    def _update_ema(self, s: int) -> None:
        if self.ema is None:
            return
        with torch.no_grad():
            # one multi-tensor kernel instead of one per tensor (the same values on the CPU)
            names = list(self.ema)
            params = dict(self.model.nets[s].named_parameters())
            torch._foreach_lerp_([self.ema[k] for k in names],
                                 [params[k].detach() for k in names], 1.0 - self.cfg.ema)

    @contextlib.contextmanager
    def averaged(self):
        """The model with the trained scale's averaged weights in it (no-op without EMA)."""
        if self.ema is None:
            yield self.model
            return
        net = self.model.nets[self.scale]
        raw = {k: p.detach().clone() for k, p in net.named_parameters()}
        self._load_net(self.scale, self.ema)
        try:
            yield self.model
        finally:
            self._load_net(self.scale, raw)

    def _load_net(self, s: int, values: dict) -> None:
        with torch.no_grad():
            for k, p in self.model.nets[s].named_parameters():
                p.copy_(values[k])

    def _lr(self, s: int, step: int) -> float:
        total = self.cfg.steps[s]
        if step < self.cfg.warmup:
            return self.cfg.lr * (step + 1) / self.cfg.warmup
        progress = (step - self.cfg.warmup) / max(1, total - self.cfg.warmup)
        return self.cfg.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * progress)))

    # ------------------------------------------------------------------ one step
    def crop_size(self, s: int) -> int:
        return crop_size(self.cfg, self.model_config, self.samples, s)

    def batch(self, s: int, step: int) -> dict:
        """Tensors of one batch of crops of scale s (deterministic in seed, s, step)."""
        return make_batch(self.cfg, self.model_config, self.samples, s, step)

    def _batches(self, s: int, start: int, total: int):
        """Batches for steps start..total-1, built by worker processes when cfg.workers > 0."""
        if self.cfg.workers <= 0:
            return (self.batch(s, step) for step in range(start, total))
        loader = torch.utils.data.DataLoader(
            _BatchSource(self.cfg, self.model_config, self.samples, s),
            batch_size=None, sampler=range(start, total), num_workers=self.cfg.workers,
            pin_memory=self.device.type == "cuda", prefetch_factor=4,
            worker_init_fn=_one_thread)
        return iter(loader)

    def predict_coarser(self, s: int, g: list) -> torch.Tensor | None:
        """P_{s+1} of the frozen coarser networks on the crop's coarser inputs."""
        if s == self.model_config.levels:
            return None
        with torch.no_grad():
            return self._compiled("coarser", s, self._predict_coarser)(s, g)

    def _predict_coarser(self, s: int, g: list) -> torch.Tensor:
        p = None
        for t in reversed(range(s + 1, self.model_config.levels + 1)):
            with self._autocast():
                p = self.model.forward_scale(t, g[t - s], p)
            p = p.float()
        return p

    def _scale_loss(self, s: int, g: torch.Tensor, coarser, vertex, edge, scored, valid,
                    quadric) -> tuple[torch.Tensor, dict]:
        """Scale s's loss and its parts (0-d tensors) on one batch: what ``cfg.compile``
        traces, so it takes tensors only."""
        with self._autocast():
            pred = self.model.forward_scale(s, g, coarser)
        return self.losses[s].terms(pred.float(), vertex, edge, scored, valid, quadric)

    def _compiled(self, role: str, s: int, fn):
        """``fn`` itself, or once per (role, scale) its torch.compile'd form (``cfg.compile``)."""
        mode = self.cfg.compile
        if not mode:
            return fn
        key = (role, s)
        if key not in self._compiled_fns:
            # every batch of a scale has one shape: no dynamic shapes, and no graph breaks
            self._compiled_fns[key] = torch.compile(fn, fullgraph=True, dynamic=False,
                                                    **COMPILE_MODES[mode])
        return self._compiled_fns[key]

    def _autocast(self):
        use = self.cfg.amp and self.device.type == "cuda"
        return torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=use)

    def train_step(self, s: int, step: int, batch: dict | None = None) -> dict:
        if batch is None:
            batch = self.batch(s, step)
        batch = {k: ([t.to(self.device, non_blocking=True) for t in v] if isinstance(v, list)
                     else v.to(self.device, non_blocking=True)) for k, v in batch.items()}
        self.model.nets[s].train()
        for group in self.optimizer.param_groups:
            group["lr"] = self._lr(s, step)
        try:
            loss, parts = self._loss_and_gradients(s, batch)
        except Exception as exc:  # compilers fail with many exception types
            if not self.cfg.compile or s in self._compiled_scales:
                raise
            self._compile_failed(s, exc)
            loss, parts = self._loss_and_gradients(s, batch)
        if self.cfg.compile:
            self._compiled_scales.add(s)
        torch.nn.utils.clip_grad_norm_(self.model.nets[s].parameters(), 1.0)
        self.optimizer.step()
        self._update_ema(s)
        # detached 0-d tensors, copied out of any CUDA graph's buffers: float() them when
        # logging, so the step does not wait for the GPU
        return {k: v.detach().clone() for k, v in {"loss": loss, **parts}.items()}

    def _loss_and_gradients(self, s: int, batch: dict) -> tuple[torch.Tensor, dict]:
        """Forward, loss and backward of one batch (the weights are not touched yet)."""
        if self.cfg.compile:
            # CUDA graphs (reduce-overhead) may reuse the last step's buffers from here on
            torch.compiler.cudagraph_mark_step_begin()
        coarser = self.predict_coarser(s, batch["g"])
        loss, parts = self._compiled("loss", s, self._scale_loss)(
            s, batch["g"][0], coarser, batch["vertex"], batch["edge"],
            batch["surface"] & batch["valid"], batch["valid"], batch.get("quadric"))
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        return loss, parts

    def _compile_failed(self, s: int, exc: Exception) -> None:
        """A scale's first compiled step failed: train on eagerly rather than lose the run (a
        GPU machine's window is minutes), and say so in the log and the checkpoint's record."""
        log.warning("--compile %s failed on scale %d, training on eagerly: %s: %s",
                    self.cfg.compile, s, type(exc).__name__, str(exc)[:500])
        self.cfg.compile = ""
        self._compiled_fns.clear()
        if self.sessions:
            self.sessions[-1]["hardware"] = _hardware(self.device, self.cfg)
            self.sessions[-1]["compile_error"] = f"{type(exc).__name__}: {str(exc)[:300]}"

    # ------------------------------------------------------------------ loop
    def run(self, progress: bool = True) -> Path | None:
        """Train the remaining steps; the final checkpoint's path, or None when ``max_seconds``
        ran out first (the state is saved and ``resume`` continues exactly)."""
        from tqdm import tqdm

        levels = self.model_config.levels
        started = time.perf_counter()
        if self.scale > 0 or self.step < self.cfg.steps[0]:  # steps left to run here
            self.sessions.append({"hardware": _hardware(self.device, self.cfg),
                                  "from": {"scale": self.scale, "step": self.step}})
        for s in reversed(range(levels + 1)):
            if s > self.scale:
                continue  # finished before a resume
            if s < self.scale:
                self.begin_scale(s)
            total = self.cfg.steps[s]
            bar = tqdm(total=total, initial=self.step, desc=f"scale {s}", disable=not progress)
            window: list[dict] = []
            batches = self._batches(s, self.step, total)
            while self.step < total:
                start = time.perf_counter()
                batch = next(batches)
                self.data_seconds += time.perf_counter() - start
                window.append(self.train_step(s, self.step, batch))
                self.seconds += time.perf_counter() - start
                self.step += 1
                bar.update(1)
                if self.step % self.cfg.log_every == 0 or self.step == total:
                    entry = {"scale": s, "step": self.step, "seconds": round(self.seconds, 1),
                             "data_seconds": round(self.data_seconds, 1),
                             "lr": self._lr(s, self.step - 1),
                             **{k: float(np.mean([float(w[k]) for w in window]))
                                for k in window[0]}}
                    self.log.append(entry)
                    bar.set_postfix(v=f"{entry['vertex']:.4f}", e=f"{entry['edge']:.4f}")
                    window = []
                if s == 0 and self.step in self.cfg.val_steps:
                    self.snapshot()
                if self.step % self.cfg.save_every == 0:
                    self.save_state()
                if self.cfg.max_seconds and time.perf_counter() - started > self.cfg.max_seconds \
                        and self.step < total:
                    bar.close()
                    self.save_state()
                    return None
            bar.close()
            if self.ema is not None:  # finer scales train on (and the checkpoint keeps) the average
                self._load_net(s, self.ema)
                self.ema = self._start_ema(s)
            self.save_state()
        return self.finish(self.validate())

    def validate(self) -> dict:
        """CD/F1/... of the averaged weights on the held-out samples ({} without ``cfg.val``)."""
        with self.averaged() as model:
            return self._validate(model)

    def _validate(self, model) -> dict:
        from .validate import validate_model

        if not self.cfg.val:
            return {}
        return validate_model(model.eval(), self.cfg.val, count=self.cfg.val_count,
                              n_samples=self.cfg.val_samples)

    def snapshot(self) -> Path:
        """A learning-curve point: the checkpoint of the finest scale's current step (its
        averaged weights, as ``finish`` keeps), scored on the held-out samples if any. The
        learning rate is still on the run's schedule, so a point of a long run is not what a
        run of that many steps would end with."""
        from ..checkpoint import save_checkpoint

        with self.averaged() as model:
            metrics = self._validate(model)
            self.log.append({"scale": 0, "step": self.step, "seconds": round(self.seconds, 1),
                             "val": metrics})
            return save_checkpoint(model.eval(), self.out / f"step-{self.step:06d}",
                                   training=self.training_record(), metrics=metrics)

    def training_record(self) -> dict:
        """What a checkpoint says about how it was trained (data, recipe, steps, hardware), and
        its lineage: the runs it continues through ``--init``, oldest first, then this one."""
        record = {
            "recipe": "agndc_core.training (procedural shapes, training/data.py); finest scale: "
                      "correction to the surface nets vertex, no edge loss; loss only on cells "
                      "with `margin` points of real context; zero-initialised last vertex "
                      "layers and snake offsets",
            "data": {"folder": self.cfg.data, "samples": len(self.samples),
                     "seeds": [int(min(x.recipe["seed"] for x in self.samples)),
                               int(max(x.recipe["seed"] for x in self.samples))],
                     "resolutions": [int(min(x.recipe["resolution"] for x in self.samples)),
                                     int(max(x.recipe["resolution"] for x in self.samples))],
                     "augmentation": "random rotation (part of the samples), resolution, "
                                     "sub-voxel shift; 48 axis permutations x flips per crop"},
            "config": asdict(self.cfg),
            "steps_per_scale": list(self.cfg.steps),
            "train_seconds": round(self.seconds, 1),
            "data_wait_seconds": round(self.data_seconds, 1),
            "hardware": _hardware_of(self.sessions) or _hardware(self.device, self.cfg),
            "sessions": self.sessions,
            "final_losses": [e for e in self.log if e["step"] == self.cfg.steps[e["scale"]]],
            "steps_done": {"scale": self.scale, "step": self.step},
            **({"warm_start": self.warm_start} if self.warm_start else {}),
        }
        earlier = []
        if self.init_training is not None:
            earlier = (self.init_training.get("lineage")
                       or [_lineage_entry(self.init_training, self.cfg.init)])
        record["lineage"] = earlier + [_lineage_entry(record, self.cfg.out)]
        record["total_train_seconds"] = round(sum(e.get("train_seconds", 0.0)
                                                  for e in record["lineage"]), 1)
        return record

    def finish(self, metrics: dict) -> Path:
        from ..checkpoint import save_checkpoint

        path = save_checkpoint(self.model.eval(), self.out / "final",
                               training=self.training_record(), metrics=metrics)
        self._write_run_json(done=True, metrics=metrics)
        return path

    # ------------------------------------------------------------------ resume
    def save_state(self) -> None:
        """Model, loss weights and optimiser state, sharded under MAX_FILE_BYTES per file."""
        self.out.mkdir(parents=True, exist_ok=True)
        tensors = {f"model.{k}": v for k, v in self.model.state_dict().items()}
        tensors.update({f"loss.{k}": v for k, v in self.losses.state_dict().items()})
        tensors.update({f"ema.{k}": v for k, v in (self.ema or {}).items()})
        opt = self.optimizer.state_dict()
        for index, state in opt["state"].items():
            for name, value in state.items():
                tensors[f"optim.{index}.{name}"] = torch.as_tensor(value)
        shards = save_sharded(tensors, self.out, "state")
        self._write_run_json(done=False, param_groups=opt["param_groups"], shards=shards)

    def _write_run_json(self, done: bool, **extra) -> None:
        info = {"config": asdict(self.cfg), "model_config": self.model_config.to_dict(),
                "scale": self.scale, "step": self.step, "seconds": self.seconds,
                "data_seconds": self.data_seconds,
                "done": done, "log": self.log, "sessions": self.sessions, **extra}
        (self.out / "run.json").write_text(json.dumps(info, indent=1))

    def resume(self) -> bool:
        """Load ``run.json`` and its state shards if present; True if resumed."""
        info_path = self.out / "run.json"
        if not info_path.exists():
            return False
        info = json.loads(info_path.read_text())
        if not info.get("shards") or not all((self.out / n).exists() for n in info["shards"]):
            return False
        if info["model_config"] != self.model_config.to_dict():
            raise AGNDCError(f"{info_path}: the run was started with another model config")
        tensors = {k: v.to(self.device) for k, v in load_sharded(self.out, info["shards"]).items()}
        self.model.load_state_dict({k[6:]: v for k, v in tensors.items()
                                    if k.startswith("model.")})
        self.losses.load_state_dict({k[5:]: v for k, v in tensors.items()
                                     if k.startswith("loss.")})
        self.scale, self.step = info["scale"], info["step"]
        self.seconds, self.log = info["seconds"], info["log"]
        self.data_seconds = info.get("data_seconds", 0.0)
        # a run.json from before the trainer kept its sessions: where its steps ran is unknown
        unknown = [{"hardware": "not recorded", "from": {"scale": self.model_config.levels,
                                                         "step": 0}}]
        self.sessions = info.get("sessions", unknown)
        self.optimizer = self._optimizer(self.scale)
        self.ema = self._start_ema(self.scale)
        if self.ema is not None:
            saved = {k[4:]: v for k, v in tensors.items() if k.startswith("ema.")}
            if saved.keys() != self.ema.keys():
                raise AGNDCError(f"{info_path}: the saved state has no weight average for "
                                 "this scale (was the run started without --ema?)")
            self.ema = {k: v.clone() for k, v in saved.items()}
        opt_state: dict = {}
        for key, value in tensors.items():
            if key.startswith("optim."):
                _, index, name = key.split(".", 2)
                opt_state.setdefault(int(index), {})[name] = value
        if "param_groups" in info:
            self.optimizer.load_state_dict({"state": opt_state,
                                            "param_groups": info["param_groups"]})
        return True


def _load_matching(model: torch.nn.Module, source: dict) -> dict:
    """Copy into ``model`` every tensor of ``source`` with the same name and shape; what was
    loaded, and the modules (``nets.S.module``) that start fresh or are left out."""
    target = model.state_dict()
    shared = {k: v for k, v in source.items() if k in target and target[k].shape == v.shape}
    model.load_state_dict(shared, strict=False)

    def modules(names):
        return sorted({".".join(n.split(".")[:3]) for n in names})

    return {"loaded": len(shared), "fresh": modules(set(target) - set(shared)),
            "dropped": modules(set(source) - set(shared))}


#: the options a lineage entry keeps of each run (the rest are in that run's own record)
LINEAGE_OPTIONS = ("init", "batch", "lr", "seed", "crop", "margin", "quadric_floor",
                   "crease_weight", "ema", "outside_crops", "random_phase", "binary_targets")


def _lineage_entry(training: dict, run) -> dict:
    """One run of a lineage, from its checkpoint's training record: what it trained on, how,
    where and for how long."""
    config = training.get("config") or {}
    entry = {"run": str(run), **{k: config[k] for k in LINEAGE_OPTIONS if k in config}}
    for key in ("data", "steps_per_scale", "train_seconds", "hardware", "sessions"):
        if key in training:
            entry[key] = training[key]
    return entry


def _hardware_of(sessions: list[dict]) -> str:
    """One line for the processes that ran a run's steps: the hardware when one machine ran
    every step, else each process's with the scale and step it began at."""
    kinds = {entry["hardware"] for entry in sessions}
    if len(kinds) <= 1:
        return next(iter(kinds), "")
    return "; ".join(f"{e['hardware']} from scale {e['from']['scale']} step {e['from']['step']}"
                     for e in sessions)


def _hardware(device: torch.device, cfg: TrainConfig) -> str:
    """What the steps ran on, for the checkpoint's record (step times depend on it)."""
    if device.type == "cuda":
        where = torch.cuda.get_device_name(device) + (", bf16 autocast" if cfg.amp else "")
    else:
        where = f"CPU, {cfg.threads} threads"
    compiled = f", torch.compile {cfg.compile}" if cfg.compile else ""
    return f"{where}, torch {torch.__version__}{compiled}, {cfg.workers} data workers"


def _load_folder(folder, levels: int, workers: int = 0) -> list[SparseSample]:
    """Samples of one folder, or of several separated by commas, in path order; read by
    ``workers`` processes when > 1 (5,000 samples took ~2 min in one process on a GPU
    machine)."""
    from functools import partial

    paths = sorted(p for f in str(folder).split(",") for p in Path(f).glob("sample_*.npz"))
    if not paths:
        raise AGNDCError(f"no training samples (sample_*.npz) in {folder}; build them with "
                         "`agndc train-data`")
    read = partial(_read_sparse, levels=levels)
    if workers <= 1 or len(paths) < 2:
        return [read(path) for path in paths]
    from multiprocessing import get_context

    with get_context("spawn").Pool(workers) as pool:
        return pool.map(read, paths, chunksize=8)


def _read_sparse(path, levels: int) -> SparseSample:
    return SparseSample(load_sample(path), levels)


def crop_size(cfg: TrainConfig, model_config, samples: list[SparseSample], s: int) -> int:
    """Crop edge of scale s: the configured one, at most the largest lattice, block-aligned."""
    block = 2 ** (model_config.levels - s)
    largest = max(max(x.shapes[s]) for x in samples)
    crop = cfg.crop[s] if isinstance(cfg.crop, (list, tuple)) else cfg.crop
    size = min(int(crop), -(-largest // block) * block)
    return max(block, size // block * block)


def make_batch(cfg: TrainConfig, model_config, samples: list[SparseSample], s: int,
               step: int) -> dict:
    """Tensors of one batch of crops of scale s, a pure function of (cfg.seed, s, step).

    Returns:
        {"g": [(B, n, n, n) bool of scale s, (B, n/2, ...) of s + 1, ...],
         "vertex": (B, n, n, n, 3) float32, "edge": (B, n, n, n, 3) bool,
         "surface": (B, n, n, n) bool, "valid": (B, n, n, n) bool (``crops.valid_cells``),
         "quadric": (B, n, n, n, 6) float32 when the samples have normal quadrics}
    """
    rng = np.random.default_rng([cfg.seed, s, step])
    size = crop_size(cfg, model_config, samples, s)
    align = model_config.window * 2 ** (model_config.levels - s)
    margins = cfg.margin if isinstance(cfg.margin, (list, tuple)) else [cfg.margin] * (s + 1)
    margin = int(margins[s]) if s < len(margins) else 0
    crops = []
    for i in rng.integers(len(samples), size=cfg.batch):
        sample = samples[i]
        origin = random_crop_origin(sample.cells[s], size, 1 if cfg.random_phase else align,
                                    rng, margin, dims=sample.shapes[s], outside=cfg.outside_crops)
        perm, flips = rng.permutation(3), rng.random(3) < 0.5
        # a dense window one alignment step larger on each side (make_crop reads one cell
        # before the crop). The window pools its own coarser inputs: on the lattice's own
        # pyramid for an aligned origin, else on the pyramid of the part moved by the phase,
        # whose scale-s labels are the same cells' (tests/core/test_training.py)
        window = sample.window(s, np.asarray(origin) - align, [size + 2 * align] * 3)
        grids = [None] * s + window.pop("grids")
        crop = make_crop(window, grids, s, size, [align] * 3, perm, flips)
        crop["valid"] = valid_cells(origin, size, sample.shapes[s], margin, perm, flips)
        if cfg.binary_targets and s == 0 and "quadric" in crop:
            crop["vertex"] = binary_visible_vertex(crop["vertex"], crop["quadric"],
                                                   surface_nets_lattice(crop["g"][0]))
        crops.append(crop)
    out = {"g": [torch.from_numpy(np.stack([c["g"][k] for c in crops]))
                 for k in range(len(crops[0]["g"]))]}
    for key in ("vertex", "edge", "surface", "valid", "quadric"):
        if all(key in c for c in crops):
            out[key] = torch.from_numpy(np.stack([c[key] for c in crops]))
    return out


class _BatchSource(torch.utils.data.Dataset):
    """Map-style dataset whose item ``step`` is that step's batch (for DataLoader workers)."""

    def __init__(self, cfg, model_config, samples, s):
        self.cfg, self.model_config, self.samples, self.s = cfg, model_config, samples, s

    def __len__(self) -> int:
        return int(self.cfg.steps[self.s])

    def __getitem__(self, step: int) -> dict:
        return make_batch(self.cfg, self.model_config, self.samples, self.s, int(step))


def _one_thread(_worker: int) -> None:
    torch.set_num_threads(1)  # crop building is numpy; leave the cores to the network


def save_sharded(tensors: dict, folder: Path, stem: str) -> list[str]:
    """Write ``tensors`` as ``stem-000.safetensors``, ... each under MAX_FILE_BYTES.

    Returns the shard file names (a single tensor larger than the limit gets a shard alone).
    """
    from safetensors.torch import save_file

    shards, current, size = [], {}, 0
    for name, tensor in tensors.items():
        nbytes = tensor.numel() * tensor.element_size()
        if current and size + nbytes > MAX_FILE_BYTES:
            shards.append(current)
            current, size = {}, 0
        current[name], size = tensor.detach().cpu().contiguous(), size + nbytes
    shards.append(current)
    names = []
    for i, shard in enumerate(shards):
        name = f"{stem}-{i:03d}.safetensors"
        tmp = folder / (name + ".tmp")
        save_file(shard, str(tmp))
        tmp.replace(folder / name)
        names.append(name)
    for old in folder.glob(f"{stem}-*.safetensors"):
        if old.name not in names:
            old.unlink()
    return names


def load_sharded(folder: Path, names: list[str]) -> dict:
    from safetensors.torch import load_file

    tensors = {}
    for name in names:
        tensors.update(load_file(str(folder / name)))
    return tensors


def train(cfg: TrainConfig, resume: bool = False, progress: bool = True) -> Path | None:
    """Run (or resume) a training run; the final checkpoint's weights path, or None if
    ``cfg.max_seconds`` ran out first (resume to continue)."""
    trainer = Trainer(cfg)
    if resume and trainer.resume():
        log.info("resumed %s at scale %d, step %d", cfg.out, trainer.scale, trainer.step)
    return trainer.run(progress=progress)
