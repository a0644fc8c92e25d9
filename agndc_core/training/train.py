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

import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from ..errors import AGNDCError
from .crops import make_crop, random_crop_origin, sample_pyramid
from .data import load_sample


@dataclass
class TrainConfig:
    data: str  # folder of samples written by data.build_dataset
    out: str  # run directory
    val: str | None = None  # folder of held-out samples (CD/F1 after the finest scale)
    model: dict = field(default_factory=dict)  # AGNDCConfig fields
    steps: list = field(default_factory=lambda: [1000, 500, 500])  # per scale s = 0..levels
    batch: int = 4
    crop: list = field(default_factory=lambda: [24, 16, 32])  # crop edge per scale s (clipped)
    lr: float = 2e-3
    warmup: int = 50
    seed: int = 0
    threads: int = 2
    log_every: int = 25
    save_every: int = 100
    val_count: int = 8
    val_samples: int = 20_000  # surface samples per mesh for the validation metrics


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
        self.model = AGNDCCascade(self.model_config)
        self.losses = torch.nn.ModuleList([AGNDCLoss() for _ in range(levels + 1)])
        self.samples = _load_folder(cfg.data, levels)
        self.log: list[dict] = []
        self.scale, self.step = levels, 0  # next step to run
        self.optimizer = self._optimizer(self.scale)
        self.seconds = 0.0

    # ------------------------------------------------------------------ schedule
    def _optimizer(self, s: int):
        params = list(self.model.nets[s].parameters()) + list(self.losses[s].parameters())
        return torch.optim.AdamW(params, lr=self.cfg.lr, weight_decay=1e-4)

    def _lr(self, s: int, step: int) -> float:
        total = self.cfg.steps[s]
        if step < self.cfg.warmup:
            return self.cfg.lr * (step + 1) / self.cfg.warmup
        progress = (step - self.cfg.warmup) / max(1, total - self.cfg.warmup)
        return self.cfg.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * progress)))

    # ------------------------------------------------------------------ one step
    def crop_size(self, s: int) -> int:
        block = 2 ** (self.model_config.levels - s)
        largest = max(max(x["grids"][s].shape) for x in self.samples)
        crop = self.cfg.crop[s] if isinstance(self.cfg.crop, (list, tuple)) else self.cfg.crop
        size = min(int(crop), -(-largest // block) * block)
        return max(block, size // block * block)

    def batch(self, s: int, step: int) -> dict:
        """Tensors of one batch of crops of scale s (deterministic in seed, s, step)."""
        rng = np.random.default_rng([self.cfg.seed, s, step])
        size = self.crop_size(s)
        align = self.model_config.window * 2 ** (self.model_config.levels - s)
        crops = []
        for i in rng.integers(len(self.samples), size=self.cfg.batch):
            sample = self.samples[i]
            origin = random_crop_origin(sample[f"surface{s}"], size, align, rng)
            crops.append(make_crop(sample, sample["grids"], s, size, origin,
                                   rng.permutation(3), rng.random(3) < 0.5))
        out = {"g": [torch.from_numpy(np.stack([c["g"][k] for c in crops]))
                     for k in range(len(crops[0]["g"]))]}
        for key in ("vertex", "edge", "surface"):
            out[key] = torch.from_numpy(np.stack([c[key] for c in crops]))
        return out

    def predict_coarser(self, s: int, g: list) -> torch.Tensor | None:
        """P_{s+1} of the frozen coarser networks on the crop's coarser inputs."""
        levels = self.model_config.levels
        if s == levels:
            return None
        p = None
        with torch.no_grad():
            for t in reversed(range(s + 1, levels + 1)):
                p = self.model.forward_scale(t, g[t - s], p)
        return p

    def train_step(self, s: int, step: int) -> dict:
        batch = self.batch(s, step)
        coarser = self.predict_coarser(s, batch["g"])
        self.model.nets[s].train()
        for group in self.optimizer.param_groups:
            group["lr"] = self._lr(s, step)
        pred = self.model.forward_scale(s, batch["g"][0], coarser)
        loss, parts = self.losses[s](pred, batch["vertex"], batch["edge"], batch["surface"])
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.model.nets[s].parameters(), 1.0)
        self.optimizer.step()
        return {"loss": float(loss.detach()), **parts}

    # ------------------------------------------------------------------ loop
    def run(self, progress: bool = True) -> Path:
        from tqdm import tqdm

        levels = self.model_config.levels
        for s in reversed(range(levels + 1)):
            if s > self.scale:
                continue  # finished before a resume
            if s < self.scale:
                self.scale, self.step = s, 0
                self.optimizer = self._optimizer(s)
            total = self.cfg.steps[s]
            bar = tqdm(total=total, initial=self.step, desc=f"scale {s}", disable=not progress)
            window: list[dict] = []
            while self.step < total:
                start = time.perf_counter()
                window.append(self.train_step(s, self.step))
                self.seconds += time.perf_counter() - start
                self.step += 1
                bar.update(1)
                if self.step % self.cfg.log_every == 0 or self.step == total:
                    entry = {"scale": s, "step": self.step, "seconds": round(self.seconds, 1),
                             "lr": self._lr(s, self.step - 1),
                             **{k: float(np.mean([w[k] for w in window])) for k in window[0]}}
                    self.log.append(entry)
                    bar.set_postfix(v=f"{entry['vertex']:.4f}", e=f"{entry['edge']:.4f}")
                    window = []
                if self.step % self.cfg.save_every == 0:
                    self.save_state()
            bar.close()
            self.save_state()
        metrics = self.validate() if self.cfg.val else {}
        return self.finish(metrics)

    def validate(self) -> dict:
        from .validate import validate_model

        self.model.eval()
        return validate_model(self.model, self.cfg.val, count=self.cfg.val_count,
                              n_samples=self.cfg.val_samples)

    def finish(self, metrics: dict) -> Path:
        from ..checkpoint import save_checkpoint

        training = {
            "recipe": "agndc_core.training (procedural CAD parts, training/data.py)",
            "data": {"folder": self.cfg.data, "samples": len(self.samples),
                     "seeds": [int(min(x["recipe"]["seed"] for x in self.samples)),
                               int(max(x["recipe"]["seed"] for x in self.samples))],
                     "augmentation": "rotation 50%, resolution 40-64, sub-voxel shift, "
                                     "axis permutation + flips"},
            "config": asdict(self.cfg),
            "steps_per_scale": list(self.cfg.steps),
            "train_seconds": round(self.seconds, 1),
            "final_losses": [e for e in self.log if e["step"] == self.cfg.steps[e["scale"]]],
        }
        path = save_checkpoint(self.model.eval(), self.out / "final", training=training,
                               metrics=metrics)
        self._write_run_json(done=True, metrics=metrics)
        return path

    # ------------------------------------------------------------------ resume
    def save_state(self) -> None:
        from safetensors.torch import save_file

        self.out.mkdir(parents=True, exist_ok=True)
        tensors = {f"model.{k}": v.detach().contiguous() for k, v in
                   self.model.state_dict().items()}
        tensors.update({f"loss.{k}": v.detach().contiguous()
                        for k, v in self.losses.state_dict().items()})
        opt = self.optimizer.state_dict()
        for index, state in opt["state"].items():
            for name, value in state.items():
                tensors[f"optim.{index}.{name}"] = torch.as_tensor(value).contiguous()
        tmp = self.out / "state.safetensors.tmp"
        save_file(tensors, str(tmp))
        tmp.replace(self.out / "state.safetensors")
        self._write_run_json(done=False, param_groups=opt["param_groups"])

    def _write_run_json(self, done: bool, **extra) -> None:
        info = {"config": asdict(self.cfg), "model_config": self.model_config.to_dict(),
                "scale": self.scale, "step": self.step, "seconds": self.seconds,
                "done": done, "log": self.log, **extra}
        (self.out / "run.json").write_text(json.dumps(info, indent=1))

    def resume(self) -> bool:
        """Load ``state.safetensors`` + ``run.json`` if present; True if resumed."""
        from safetensors.torch import load_file

        state_path, info_path = self.out / "state.safetensors", self.out / "run.json"
        if not (state_path.exists() and info_path.exists()):
            return False
        info = json.loads(info_path.read_text())
        if info["model_config"] != self.model_config.to_dict():
            raise AGNDCError(f"{info_path}: the run was started with another model config")
        tensors = load_file(str(state_path))
        self.model.load_state_dict({k[6:]: v for k, v in tensors.items()
                                    if k.startswith("model.")})
        self.losses.load_state_dict({k[5:]: v for k, v in tensors.items()
                                     if k.startswith("loss.")})
        self.scale, self.step = info["scale"], info["step"]
        self.seconds, self.log = info["seconds"], info["log"]
        self.optimizer = self._optimizer(self.scale)
        opt_state: dict = {}
        for key, value in tensors.items():
            if key.startswith("optim."):
                _, index, name = key.split(".", 2)
                opt_state.setdefault(int(index), {})[name] = value
        if "param_groups" in info:
            self.optimizer.load_state_dict({"state": opt_state,
                                            "param_groups": info["param_groups"]})
        return True


def _load_folder(folder, levels: int) -> list[dict]:
    paths = sorted(Path(folder).glob("sample_*.npz"))
    if not paths:
        raise AGNDCError(f"no training samples (sample_*.npz) in {folder}; build them with "
                         "`agndc train-data`")
    samples = []
    for path in paths:
        sample = load_sample(path)
        keep = {"recipe": sample["recipe"], "grids": sample_pyramid(sample["lattice"], levels)}
        for s in range(levels + 1):
            keep[f"vertex{s}"] = sample[f"vertex{s}"].astype(np.float32)
            keep[f"edge{s}"] = sample[f"edge{s}"]
            keep[f"surface{s}"] = sample[f"surface{s}"]
        samples.append(keep)
    return samples


def train(cfg: TrainConfig, resume: bool = False, progress: bool = True) -> Path:
    """Run (or resume) a training run; returns the final checkpoint's weights path."""
    trainer = Trainer(cfg)
    if resume and trainer.resume():
        print(f"resumed {cfg.out} at scale {trainer.scale}, step {trainer.step}")
    return trainer.run(progress=progress)
