"""Benchmark of the trainer's throughput: crops per second of finest-scale steps, per batch size
and ``--compile`` mode, against eager steps of the first variant measured in the same run.

A width-16 step on a GPU is bound by launching its kernels (docs/experiments/step-times.md:
0.31 s per batch of 16 crops on an H100), so the crops per second grow with the batch and with
CUDA graphs far more than with faster kernels. Each variant gets its own ``Trainer`` (the shipped
AGNDC's architecture, random weights, scale 0 with the frozen coarser scales), the same few
batches built once and reused (on the CPU, pinned, copied to the device inside the step as in
training), ``--warmup`` steps (torch.compile's compilation happens there: its time is printed)
and ``--steps`` timed steps. The loss of the first batch is printed beside eager's for the same
batch size, so a compiled variant that computes something else shows. The crops per second that
one process builds (``make_batch``) are printed too: the trainer's data workers must keep up.

Usage: python benchmarks/bench_training_throughput.py --data FOLDER [--device cuda]
       [--variants eager:16,reduce-overhead:16,reduce-overhead:64] [--steps 20] [--warmup 3]
       [--width 16] [--threads 2]
FOLDER holds training samples (``agndc train-data``); a handful is enough.
"""

import argparse
import os
import tempfile
import time

import torch

from agndc_core.training.train import COMPILE_MODES, TrainConfig, Trainer


def parse_variants(text: str) -> list[tuple[str, int]]:
    """"eager:16,cudagraphs:64" -> [("", 16), ("cudagraphs", 64)]."""
    out = []
    for item in text.split(","):
        mode, _, batch = item.strip().partition(":")
        mode = "" if mode == "eager" else mode
        if mode and mode not in COMPILE_MODES:
            raise SystemExit(f"unknown mode {mode!r}: eager or one of {', '.join(COMPILE_MODES)}")
        out.append((mode, int(batch)))
    return out


def sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def run_variant(args, mode: str, batch_size: int, batches: dict, out: str) -> dict:
    cfg = TrainConfig(data=args.data, out=out, steps=[10, 0, 0], batch=batch_size,
                      threads=args.threads, device=args.device, compile=mode, ema=0.99,
                      outside_crops=True, quadric_floor=1.0,
                      model={"width": args.width, "snake_kernel": 5, "band_radius": 4,
                             "surface_nets_prior": False})
    trainer = Trainer(cfg)
    trainer.begin_scale(0)
    if batch_size not in batches:
        start = time.perf_counter()
        built = [trainer.batch(0, k) for k in range(args.distinct)]
        seconds = time.perf_counter() - start
        if trainer.device.type == "cuda":
            built = [{k: [t.pin_memory() for t in v] if isinstance(v, list) else v.pin_memory()
                      for k, v in b.items()} for b in built]
        batches[batch_size] = (built, args.distinct * batch_size / seconds)
    built, _ = batches[batch_size]
    device = trainer.device
    start = time.perf_counter()
    first = float(trainer.train_step(0, 0, built[0])["loss"])
    for k in range(1, args.warmup):
        trainer.train_step(0, k, built[k % len(built)])
    sync(device)
    warmup = time.perf_counter() - start
    start = time.perf_counter()
    for k in range(args.steps):
        trainer.train_step(0, args.warmup + k, built[k % len(built)])
    sync(device)
    seconds = (time.perf_counter() - start) / args.steps
    return {"mode": mode or "eager", "batch": batch_size, "step": seconds,
            "crops": batch_size / seconds, "warmup": warmup, "first_loss": first}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--variants", default="eager:4,aot_eager:4",
                        help="MODE:BATCH,... (MODE: eager or a --compile mode); the first is "
                        "the baseline")
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--warmup", type=int, default=3)
    parser.add_argument("--distinct", type=int, default=4, help="distinct batches per size")
    parser.add_argument("--width", type=int, default=16)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()

    device = torch.device(args.device)
    where = torch.cuda.get_device_name(device) if device.type == "cuda" else \
        f"CPU, {args.threads} threads"
    print(f"{where}, torch {torch.__version__}, width {args.width}, load average "
          f"{os.getloadavg()[0]:.2f} before")
    batches: dict = {}
    rows = []
    for mode, batch_size in parse_variants(args.variants):
        with tempfile.TemporaryDirectory() as out:
            rows.append(run_variant(args, mode, batch_size, batches, out))
        r = rows[-1]
        print(f"  {r['mode']:>15} batch {r['batch']:4d}: {r['step'] * 1000:8.1f} ms/step "
              f"{r['crops']:8.1f} crops/s  {r['crops'] / rows[0]['crops']:6.2f}x  "
              f"warm-up {r['warmup']:6.1f} s  first loss {r['first_loss']:.6f}", flush=True)
    eager = {r["batch"]: r["first_loss"] for r in rows if r["mode"] == "eager"}
    for r in rows:
        if r["mode"] != "eager" and r["batch"] in eager:
            print(f"  {r['mode']} batch {r['batch']}: first loss differs from eager's by "
                  f"{abs(r['first_loss'] - eager[r['batch']]):.2e}")
    for size, (_, rate) in batches.items():
        print(f"  building batches of {size}: {rate:.0f} crops/s in one process")
    print(f"load average {os.getloadavg()[0]:.2f} after; baseline: the first row")


if __name__ == "__main__":
    main()
