"""``agndc train-data`` and ``agndc train``: the training entry points of the CLI."""

from __future__ import annotations

import json
import shutil
from pathlib import Path


def add_train_parser(sub) -> None:
    p = sub.add_parser("train-data", help="generate procedural CAD training samples (npz)")
    p.add_argument("-o", "--out", type=Path, required=True)
    p.add_argument("-n", "--count", type=int, default=480)
    p.add_argument("--seed0", type=int, default=0, help="first shape seed (val: use another range)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--resolutions", default="32,128", help="LO,HI voxels on a shape's longest "
                   "side, drawn log-uniform (default 32,128)")
    p.add_argument("--wrinkled", type=float, default=0.0, help="share of the organic and "
                   "smooth shapes whose surface gets fine wrinkles, waves 3-10 voxels long at "
                   "64 voxels, like a scan (default 0)")
    p.add_argument("--sheets", type=float, default=0.0, help="share of the samples that are "
                   "thin sheets instead, 1.5-4 voxels thick at their resolution (default 0; "
                   "the other samples stay as they are without it)")
    p.add_argument("--tilted", type=float, default=0.0, help="share of the grid-aligned "
                   "samples (sheets aside) turned 1-15 degrees off the axes instead, like a "
                   "part modelled or scanned slightly askew (default 0)")
    p.add_argument("--spikes", type=float, default=0.0, help="share of the samples (sheets "
                   "aside) that grow 2-10 sharp spikes 0.6-3 voxels in radius at the base, "
                   "5-25 voxels tall: spires, thorns, crown points (default 0)")
    p.add_argument("--layered", type=float, default=0.0, help="share of the samples (sheets "
                   "and spiky shapes aside) that are layered parts instead: caps, lids and "
                   "stepped plates of 3-12 layers 0.8-1.4 voxels thick (default 0)")
    p.add_argument("--struts", type=float, default=0.0, help="share of the samples (sheets, "
                   "spiky and layered shapes aside) that are frames of thin struts instead, "
                   "0.7-3 voxels in radius: pavilions on columns, space frames, railings, wire "
                   "rings (default 0)")
    p.add_argument("--rounds", type=float, default=0.0, help="share of the samples (sheets, "
                   "spiky, layered and strut shapes aside) that are parts of round features "
                   "along their axes instead: pins, bosses, thin-walled tubes and cups, shafts, "
                   "holes and counterbores 1.5-12 voxels in radius (default 0)")
    p.set_defaults(func=_cmd_data)

    p = sub.add_parser("val-data", help="generate the validation family (OBJ meshes and "
                       "MANIFEST.csv, for `agndc eval`): CAD, organic and printed shapes apart "
                       "from the training generator, for choosing checkpoints and recipes")
    p.add_argument("-o", "--out", type=Path, required=True)
    p.add_argument("-n", "--count", type=int, default=48)
    p.add_argument("--seed0", type=int, default=None, help="first seed (default 2,000,000; "
                   "3,000,000 with --sheets, 4,000,000 with --struts)")
    family = p.add_mutually_exclusive_group()
    family.add_argument("--sheets", action="store_true", help="the thin-sheet family instead: "
                        "flat plates 1.5-3 voxels thick at 64^3 with holes, slots and pockets")
    family.add_argument("--struts", action="store_true", help="the thin-strut family instead: "
                        "stools, lattice cubes, masts and springs of bars 0.8-3 voxels in "
                        "radius at 64^3")
    p.add_argument("--workers", type=int, default=2)
    p.set_defaults(func=_cmd_val_data)

    p = sub.add_parser("distil-data", help="copy training samples with a teacher network's "
                       "finest vertices as their labels (training a cheaper student)")
    p.add_argument("--data", type=Path, required=True, help="folder from `agndc train-data`")
    p.add_argument("-o", "--out", type=Path, required=True)
    p.add_argument("--teacher", type=Path, default=None,
                   help="checkpoint (.safetensors); default: the shipped AGNDC")
    p.add_argument("--weight", type=float, default=1.0, help="share of the teacher's vertex "
                   "in the label, 0..1 (the rest is the true vertex)")
    p.add_argument("--threads", type=int, default=1)
    p.set_defaults(func=_cmd_distil)

    p = sub.add_parser("train", help="train the AGNDC cascade (or the UNDC baseline) per scale")
    p.add_argument("--data", type=Path, required=True, help="folder from `agndc train-data`")
    p.add_argument("--val", type=Path, help="held-out samples for CD/F1 at the end")
    p.add_argument("-o", "--out", type=Path, required=True, help="run directory")
    p.add_argument("--model", default="{}", help='AGNDCConfig fields as JSON, e.g. {"width": 16}')
    p.add_argument("--undc", action="store_true", help="the UNDC baseline (one scale, plain convs)")
    p.add_argument("--steps", default="1000,500,500", help="steps per scale s = 0,1,..")
    p.add_argument("--crop", default="32,24,32", help="crop edge per scale s = 0,1,..")
    p.add_argument("--margin", default="6,4,2", help="unscored border per scale s = 0,1,.. "
                   "(cells whose context the crop cuts off)")
    p.add_argument("--device", default="cpu", help="cpu, cuda, cuda:1, ...")
    p.add_argument("--no-amp", action="store_true", help="no bf16 autocast on CUDA")
    p.add_argument("--workers", type=int, default=0, help="data-loader processes building crops")
    p.add_argument("--compile", default="", metavar="MODE", help="torch.compile each scale's "
                   "step: reduce-overhead (CUDA graphs of generated kernels) or cudagraphs (of "
                   "the eager kernels) for a GPU, where a width-16 step is bound by kernel "
                   "launches; inductor; aot_eager checks the trace on the CPU")
    p.add_argument("--init", help="warm start from this checkpoint (.safetensors)")
    p.add_argument("--init-matching", action="store_true", help="--init may differ from "
                   "--model in the ablation switches (levels, use_attention, use_snake, "
                   "use_dffm, use_crpm): load the tensors whose name and shape agree, start "
                   "the rest fresh (an ablation started from the full model)")
    p.add_argument("--max-minutes", type=float, help="save the state and stop after this much "
                   "wall time (continue with --resume): a run in chunks on a time-limited GPU "
                   "machine")
    p.add_argument("--val-steps", default="", help="finest-scale steps after which a checkpoint "
                   "step-NNNNNN.safetensors is written and the --val samples are scored (the "
                   "points of a learning curve), e.g. 100,300,1000")
    p.add_argument("--quadric-floor", type=float, default=None, help="weight of the plain "
                   "squared vertex error beside the normal quadric (default 0.1; 1 pins "
                   "vertices to their labels like MSE)")
    p.add_argument("--crease-weight", type=float, default=0.0, help="extra weight of crease "
                   "and corner cells in the vertex loss: such a cell counts 1 + this (default "
                   "0: every surface cell alike)")
    p.add_argument("--ema", type=float, default=0.0, help="decay of a moving average of the "
                   "weights that validation scores and the checkpoint keeps, e.g. 0.99 "
                   "(default 0: off)")
    p.add_argument("--outside-crops", action="store_true", help="let crops reach past the "
                   "lattice's ends, so the empty space in front of a face varies")
    p.add_argument("--random-phase", action="store_true", help="crops start at any point, "
                   "not on window boundaries: the network sees parts at every phase of its "
                   "pooling and attention windows (measured worse on the dev meshes: "
                   "docs/experiments/frame-phase.md)")
    p.add_argument("--binary-targets", action="store_true", help="finest scale: on exactly "
                   "axis-aligned faces train towards the layer's midpoint (the oracle_binary "
                   "vertex), not the true depth (from scratch: better at equal steps; continuing "
                   "a trained network: worse CD; docs/experiments/binary-targets-curriculum.md)")
    p.add_argument("--batch", type=int, default=4)
    p.add_argument("--lr", type=float, default=2e-3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--resume", action="store_true", help="continue from the run's state")
    p.add_argument("--ship", metavar="NAME", help="copy the final checkpoint into the package "
                   "as agndc_core/weights/NAME.{safetensors,json}")
    p.set_defaults(func=_cmd_train)


def _ints(text: str) -> list[int]:
    return [int(x) for x in text.split(",") if x.strip()]


def _cmd_data(args) -> int:
    from ..errors import AGNDCError
    from .data import build_dataset

    bounds = _ints(args.resolutions)
    if len(bounds) != 2:
        raise AGNDCError(f"--resolutions wants LO,HI, got {args.resolutions!r}")
    paths = build_dataset(args.out, args.count, seed0=args.seed0, workers=args.workers,
                          resolution_range=bounds, wrinkled=args.wrinkled,
                          sheets=args.sheets, tilted=args.tilted, spikes=args.spikes,
                          layered=args.layered, struts=args.struts, rounds=args.rounds)
    print(f"{len(paths)} samples in {args.out}")
    return 0


def _cmd_val_data(args) -> int:
    from collections import Counter

    from ..study.validation import write_family

    rows = write_family(args.out, args.count, args.seed0, args.workers,
                        family="sheets" if args.sheets else "struts" if args.struts else "main")
    kinds = Counter(r["kind"] for r in rows)
    print(f"{len(rows)} meshes in {args.out} ({', '.join(f'{n} {k}' for k, n in kinds.items())})")
    return 0


def _cmd_distil(args) -> int:
    from ..checkpoint import default_checkpoint_path
    from .distil import distil_dataset

    teacher = args.teacher or default_checkpoint_path("agndc")
    paths = distil_dataset(args.data, args.out, teacher, args.weight, args.threads)
    print(f"{len(paths)} samples in {args.out}, finest vertices {args.weight:g} x {teacher.name}")
    return 0


def _cmd_train(args) -> int:
    from ..checkpoint import WEIGHTS_DIR
    from ..errors import AGNDCError
    from ..nn import undc_baseline
    from .train import TrainConfig, train

    try:
        model = json.loads(args.model)
    except json.JSONDecodeError as exc:
        raise AGNDCError(f"--model is not valid JSON: {exc}") from None
    if args.undc:
        model = {**undc_baseline(model.get("width", 64)).to_dict(), **model}
    cfg = TrainConfig(data=str(args.data), out=str(args.out), val=str(args.val) if args.val
                      else None, model=model, steps=_ints(args.steps), crop=_ints(args.crop),
                      batch=args.batch, lr=args.lr, seed=args.seed, threads=args.threads,
                      margin=_ints(args.margin), device=args.device, amp=not args.no_amp,
                      workers=args.workers, compile=args.compile, init=args.init,
                      init_matching=args.init_matching, val_steps=_ints(args.val_steps),
                      max_seconds=args.max_minutes * 60 if args.max_minutes else None,
                      ema=args.ema, outside_crops=args.outside_crops,
                      random_phase=args.random_phase, binary_targets=args.binary_targets,
                      crease_weight=args.crease_weight)
    if args.quadric_floor is not None:
        cfg.quadric_floor = args.quadric_floor
    path = train(cfg, resume=args.resume)
    if path is None:
        print(f"stopped after {args.max_minutes} minutes; continue with --resume")
        return 0
    print(f"checkpoint: {path}")
    if args.ship:
        WEIGHTS_DIR.mkdir(parents=True, exist_ok=True)
        for suffix in (".safetensors", ".json"):
            shutil.copyfile(path.with_suffix(suffix), WEIGHTS_DIR / f"{args.ship}{suffix}")
        print(f"shipped as {WEIGHTS_DIR / args.ship}.safetensors")
    return 0
