"""The AGNDC cascade's band inference in numpy: the network without torch.

One function per paper module, in the order of ``nn/`` (GDFEM with LWSA and DSConv, FDM, DFFM,
CRPM), reading the same checkpoint tensors. The torch modules are the reference and the training
path; ``tests/core/test_runtime.py`` holds this one to them (1e-4 on the outputs). Features are
(R, C) float32 band rows (``band.py``); ``radius`` is the band radius an output is needed on.

    P_j = FDM(GDFEM(G_j))                                     coarsest scale
    P_s = CRPM(DFFM(F_s, u(P_{s+1})), FDM(F_s)),  F_s = GDFEM(G_s)
"""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np

from ..nn.config import AGNDCConfig
from ..nn.layout import crpm_radii, lookup_margin, relative_position_index, torus_periods
from .band import Band, scale_band, sigmoid
from .parallel import blas_single_thread, for_chunks

LAYER_NORM_EPS = 1e-5  # torch.nn.LayerNorm's default


class Conv:
    """A k x k x k convolution's weights laid out for band rows: (k^3 C_in, C_out), tap-major."""

    def __init__(self, weight: np.ndarray, bias: np.ndarray):
        c_out, c_in, k = weight.shape[:3]
        self.k, self.c_in, self.c_out = k, c_in, c_out
        taps = k ** 3
        self.weight = np.ascontiguousarray(
            weight.transpose(2, 3, 4, 1, 0).reshape(taps * c_in, c_out))
        # (C_in, k^3 C_out): the "project first" layout of narrow outputs
        self.project_first = np.ascontiguousarray(
            self.weight.reshape(taps, c_in, c_out).transpose(1, 0, 2).reshape(c_in, -1))
        # (k^3 C_out, C_out) 0/1: sums the k^3 projected taps of each output channel
        self.tap_sum = np.tile(np.eye(c_out, dtype=np.float32), (taps, 1))
        self.bias = bias


#: rows per chunk of a point-wise linear layer on the worker threads (BLAS runs one thread each)
LINEAR_CHUNK_ROWS = 16384


class Linear:
    """A 1x1x1 convolution / fully connected layer on (R, C_in) rows."""

    def __init__(self, weight: np.ndarray, bias: np.ndarray):
        self.weight_t = np.ascontiguousarray(weight.T)
        self.bias = bias

    def __call__(self, x: np.ndarray) -> np.ndarray:
        out = np.empty((x.shape[0], self.weight_t.shape[1]), dtype=np.float32)

        def work(a, b):
            np.matmul(x[a:b], self.weight_t, out=out[a:b])
            out[a:b] += self.bias

        for_chunks(x.shape[0], LINEAR_CHUNK_ROWS, work)
        return out


class Network:
    """The cascade of one checkpoint, ready for band inference (``inference.predict_lattice``).

    Args:
        config: the checkpoint's ``AGNDCConfig``; tensors: its state dict as float32 arrays.
    """

    backend = "numpy"

    def __init__(self, config: AGNDCConfig, tensors: dict[str, np.ndarray]):
        self.config = config
        self.tensors = tensors
        self._layers: dict = {}  # weights laid out for the band ops, built on first use
        self.slope = np.float32(config.act_slope)
        self.tick = None  # progress/cancel callback, called between layers (inference.py)

    @classmethod
    def from_torch(cls, model) -> Network:
        """The numpy twin of a torch ``AGNDCCascade`` (same config, its weights copied)."""
        state = {k: v.detach().cpu().numpy().astype(np.float32)
                 for k, v in model.state_dict().items()}
        return cls(model.config, state)

    @contextmanager
    def running(self, tick=None):
        """While a band evaluation runs: ``tick`` called between layers and chunks, one BLAS
        thread per worker thread (``parallel.py``)."""
        self.tick = tick
        try:
            with blas_single_thread():
                yield self
        finally:
            self.tick = None

    # ------------------------------------------------------------------ parameters
    def _layer(self, key, build):
        if key not in self._layers:
            self._layers[key] = build()
        return self._layers[key]

    def conv(self, name: str) -> Conv:
        return self._layer(("conv", name), lambda: Conv(self.tensors[name + ".weight"],
                                                        self.tensors[name + ".bias"]))

    def linear(self, name: str) -> Linear:
        return self._layer(("linear", name), lambda: Linear(self.tensors[name + ".weight"],
                                                            self.tensors[name + ".bias"]))

    def offset_rows(self, name: str, axis: int) -> Linear:
        """The rows of DSConv's offset layer that drive the snake along ``axis`` (its outputs
        are (3 snakes, 2 lateral axes, K taps), snake-major)."""
        weight, bias = self.tensors[name + ".weight"], self.tensors[name + ".bias"]
        n = weight.shape[0] // 3
        rows = slice(axis * n, (axis + 1) * n)
        return self._layer(("offset", name, axis), lambda: Linear(weight[rows], bias[rows]))

    def has(self, name: str) -> bool:
        return name + ".weight" in self.tensors or name + ".bias_table" in self.tensors

    # ------------------------------------------------------------------ layers
    def act(self, x: np.ndarray) -> np.ndarray:
        """LeakyReLU in place, in chunks (no full-size temporary)."""

        def work(a, b):
            part = x[a:b]
            np.maximum(part, part * self.slope, out=part)

        for_chunks(x.shape[0], LINEAR_CHUNK_ROWS, work)
        return x

    def _tick(self):
        if self.tick is not None:
            self.tick()

    def band_conv(self, ops: Band, x, name: str, radius: int, act: bool = True, out=None):
        self._tick()
        out = ops.conv(x, self.conv(name), radius, self.tick, out)
        return self.act(out) if act else out

    def layer_norm(self, x: np.ndarray, name: str) -> np.ndarray:
        mean = x.mean(-1, keepdims=True)
        centred = x - mean
        var = (centred * centred).mean(-1, keepdims=True)
        return centred / np.sqrt(var + LAYER_NORM_EPS) * self.tensors[name + ".weight"] \
            + self.tensors[name + ".bias"]

    def head(self, x: np.ndarray, name: str) -> np.ndarray:
        """PredictionHead: Linear, LeakyReLU, Linear."""
        return self.linear(name + ".fc2")(self.act(self.linear(name + ".fc1")(x)))

    # ------------------------------------------------------------------ GDFEM
    def gdfem(self, ops: Band, prefix: str) -> np.ndarray:
        cfg = self.config
        radius = ops.radius
        f = ops.input()
        for i in range(3):
            f = self.band_conv(ops, f, f"{prefix}.convs.{i}", min(i + 1, radius))
        f_a = ops.resample(f, radius)
        if cfg.use_attention:
            f_a = np.concatenate([self.lwsa(ops, f, f"{prefix}.lwsa", radius), f_a], -1)
        block = self.dsconv if cfg.use_snake else self.plain_block
        x = block(ops, f_a, f"{prefix}.dynamic.0", radius) + f_a
        x = block(ops, x, f"{prefix}.dynamic.1", radius) + f_a
        return block(ops, x, f"{prefix}.dynamic.2", radius)

    def plain_block(self, ops: Band, x, prefix: str, radius: int):
        return self.band_conv(ops, x, prefix + ".conv", radius)

    def dsconv(self, ops: Band, x, prefix: str, radius: int):
        """Dynamic snake convolution (``nn/snake.py``): a plain branch and three snakes."""
        cfg = self.config
        k, b = cfg.snake_kernel, cfg.snake_width
        # the fused layer's input [plain | snake x | snake y | snake z], b channels each, every
        # branch written straight into its columns (no per-branch arrays and concatenated copy)
        branches = np.empty((ops.rows(radius), 4 * b), dtype=np.float32)
        plain = self.band_conv(ops, x, prefix + ".plain", radius, out=branches[:, :b])
        for axis in range(3):
            self._tick()
            # (R, 2, K) cumulative lateral offsets of this snake's taps: one axis at a time,
            # a third of the memory of all three (40 bytes a row each)
            drift = self.offset_rows(prefix + ".offset", axis)(plain).reshape(-1, 2, k)
            offsets = snake_offsets(drift, cfg.snake_scope)
            taps = self.linear(f"{prefix}.taps.{axis}")(x)
            columns = branches[:, (axis + 1) * b:(axis + 2) * b]
            self.act(ops.snake(taps, offsets, axis, radius, out=columns))
        return self.act(self.linear(prefix + ".fuse")(branches))

    def lwsa(self, ops: Band, f, prefix: str, radius: int):
        """Local window self-attention (``nn/attention.py``) -> (R, 1) map A_s."""
        x = ops.resample(self.linear(prefix + ".proj_in")(f), radius)
        shifts = (0, self.config.window // 2)
        for i, shift in enumerate(shifts):
            x = self.window_block(ops, x, f"{prefix}.blocks.{i}", shift, radius)
        return sigmoid(self.linear(prefix + ".head")(self.layer_norm(x, prefix + ".norm")))

    def window_block(self, ops: Band, x, prefix: str, shift: int, radius: int):
        cfg = self.config
        self._tick()
        qkv = self.linear(prefix + ".qkv")(self.layer_norm(x, prefix + ".norm1"))
        bias = self.attention_bias(prefix)

        def attend(rows, token_rows):
            return window_attention(rows, token_rows, bias, cfg.heads, self._tick)

        attended = ops.windows(qkv, cfg.window, shift, attend, radius)
        x = ops.crop(x, radius) + self.linear(prefix + ".proj")(attended)
        hidden = self.act(self.linear(prefix + ".fc1")(self.layer_norm(x, prefix + ".norm2")))
        return x + self.linear(prefix + ".fc2")(hidden)

    def attention_bias(self, prefix: str) -> np.ndarray:
        """(heads, w^3, w^3) relative position bias of one window block."""
        table = self.tensors[prefix + ".bias_table"]

        def build():
            index = relative_position_index(self.config.window)
            return np.ascontiguousarray(table[index].transpose(2, 0, 1))

        return self._layer(("bias", prefix), build)

    # ------------------------------------------------------------------ FDM, DFFM, CRPM
    def fdm(self, ops: Band, f, prefix: str, radius: int):
        x = f
        for i in range(3):
            x = self.band_conv(ops, x, f"{prefix}.convs.{i}", min(ops.radius, radius + 2 - i))
        return self.head(x, prefix + ".head")

    def dffm(self, ops: Band, f, p_coarser, prefix: str, radius: int):
        """Dynamic feature fusion (``nn/dffm.py``) -> W_s (R, 6)."""
        r1 = min(ops.radius, radius + 1)
        r2 = min(ops.radius, radius + 3)
        u = ops.upsample_prediction(p_coarser, min(ops.radius, radius + 4))
        f_m = self.band_conv(ops, u, prefix + ".embed", r2)
        del u  # large row arrays are dropped as soon as they are used up (peak memory)
        both = np.concatenate([ops.crop(f, r2), f_m], -1)
        pooled = ops.down(self.linear(prefix + ".att1")(both), min(ops.half.radius, (r1 + 1) // 2))
        hidden = ops.up(pooled, r1)
        att2, reduce = self.linear(prefix + ".att2"), self.linear(prefix + ".reduce")
        reduced = np.empty((hidden.shape[0], reduce.weight_t.shape[1]), dtype=np.float32)

        def gated(a, b):  # chunks: the (R, 2w) gate is never held for every row at once
            h = hidden[a:b]
            gate = sigmoid(np.maximum(h, h * self.slope) @ att2.weight_t + att2.bias)
            gate *= both[a:b]
            out = gate @ reduce.weight_t
            out += reduce.bias
            reduced[a:b] = np.maximum(out, out * self.slope)

        for_chunks(hidden.shape[0], LINEAR_CHUNK_ROWS, gated)
        both = hidden = pooled = None  # used up: dropped before the next large arrays
        spatial = self.band_conv(ops, f, prefix + ".spatial_f", r1, act=False)
        spatial += self.band_conv(ops, f_m, prefix + ".spatial_m", r1, act=False)
        del f_m
        reduced *= sigmoid(spatial)
        return self.band_conv(ops, reduced, prefix + ".out", radius, act=False)

    def crpm(self, ops: Band, w, p_iso, prefix: str, radius: int):
        """Contour refinement (``nn/crpm.py``) -> P_s (R, 6)."""
        radii = crpm_radii(radius)
        r = {k: min(ops.radius, v) for k, v in radii.items()}
        half = ops.half
        r_half = min(half.radius, radii["half"])
        r_down = min(half.radius, radii["down"])
        both = np.concatenate([ops.crop(w, r["input"]), ops.crop(p_iso, r["input"])], -1)
        f1 = self.band_conv(ops, both, prefix + ".aggregate", r["f1"])
        x = ops.down(f1, r_down)
        for i in range(3):
            x = self.band_conv(half, x, f"{prefix}.inner.{i}", max(r_half, r_down - 1 - i))
        f2 = ops.up(x, r["f"])
        x = self.band_conv(ops, np.concatenate([ops.crop(f1, r["f"]), f2], -1),
                           prefix + ".mix.0", r["mix"])
        x = self.band_conv(ops, x, prefix + ".mix.1", radius)
        return self.head(x, prefix + ".head")

    # ------------------------------------------------------------------ one scale
    @property
    def levels(self) -> int:
        return self.config.levels

    @property
    def torus_periods(self) -> list[int]:
        cfg = self.config
        return torus_periods(cfg.levels, cfg.window if cfg.use_attention else None)

    def band_scale(self, s: int, occupancy_s, coarser=None, radius: int | None = None,
                   out_radius: int | None = None):
        """Band evaluation of scale s (``AGNDCCascade.band_scale``): (rows (R, 6), its Band)."""
        cfg = self.config
        radius = cfg.band_radius if radius is None else radius
        out_radius = radius if out_radius is None else out_radius
        periods = self.torus_periods
        margin = lookup_margin(cfg.snake_kernel, cfg.snake_scope, cfg.window)
        coarsest = s == cfg.levels
        ops = scale_band(occupancy_s, radius, periods[s], None if coarsest else periods[s + 1],
                         margin)
        prefix = f"nets.{s}"
        f = self.gdfem(ops, prefix + ".gdfem")
        if coarsest:
            return self.fdm(ops, f, prefix + ".fdm", out_radius), ops
        p_dense, p_torus = coarser
        ops.coarser = Band.everywhere(p_dense.shape[:3], periods[s + 1])
        p_rows = np.concatenate([p_torus, p_dense.reshape(-1, 6)])
        use_crpm = self.has(prefix + ".crpm.aggregate")
        r_w = out_radius if not use_crpm else min(ops.radius, crpm_radii(out_radius)["input"])
        p_iso = self.fdm(ops, f, prefix + ".fdm", r_w)
        if self.has(prefix + ".dffm.embed"):
            w = self.dffm(ops, f, p_rows, prefix + ".dffm", r_w)
        else:
            w = ops.upsample_prediction(p_rows, r_w)
        del f, p_rows  # CRPM reads W_s and P'_s only
        if use_crpm:
            return self.crpm(ops, w, p_iso, prefix + ".crpm", out_radius), ops
        return ops.crop(p_iso, out_radius) + ops.crop(w, out_radius), ops

    def add_prior(self, p0: np.ndarray, occupancy0: np.ndarray) -> np.ndarray:
        """P_0 (X, Y, Z, 6) + the surface nets prior's delta (``AGNDCCascade.add_prior``)."""
        if not self.config.surface_nets_prior:
            return p0
        from ..grid import crossed_edges, surface_cells
        from ..surfacenets import CENTRE, surface_nets_cells

        # in place, at the cells with a crossed edge only: everywhere else the delta is 0
        # (CENTRE - CENTRE), and a dense field plus a copy of P_0 cost 0.6 GB at 256³
        cells = np.flatnonzero(surface_cells(crossed_edges(occupancy0)))
        index = np.unravel_index(cells, p0.shape[:3])
        p0[index + (slice(0, 3),)] += surface_nets_cells(occupancy0, cells) - np.float32(CENTRE)
        return p0


def snake_offsets(delta: np.ndarray, scope: float) -> np.ndarray:
    """Per-tap drifts (..., 2, K) -> cumulative lateral offsets (``nn/common.snake_offsets``)."""
    k = delta.shape[-1]
    c = k // 2
    step = np.tanh(delta) * np.float32(scope)
    out = np.zeros_like(step)
    # running sums outwards from the centre tap (a loop over K, not over points: numpy's
    # cumsum along a short last axis is several times slower)
    for i in range(1, c + 1):
        out[..., c + i] = out[..., c + i - 1] + step[..., c + i]
        out[..., c - i] = out[..., c - i + 1] + step[..., c - i]
    return out


def window_attention(rows: np.ndarray, token_rows: np.ndarray, bias: np.ndarray, heads: int,
                     tick=None, chunk: int = 64) -> np.ndarray:
    """Multi-head self-attention inside windows with a relative position bias.

    Args:
        rows: (R, 3 dim) qkv rows; token_rows: (W, n) the rows of each window's n tokens;
        bias: (heads, n, n).

    Returns:
        (W, n, dim) float32 attended values (softmax(q k^T / sqrt(d) + bias) v per head).
    """
    n_win, n = token_rows.shape
    dim = rows.shape[1] // 3
    d = dim // heads
    scale = np.float32(1.0 / np.sqrt(d))
    out = np.empty((n_win, n, dim), dtype=np.float32)

    def work(a, b):
        qkv = np.take(rows, token_rows[a:b].reshape(-1), axis=0).reshape(-1, n, 3, heads, d)
        # (3, W, heads, n, d)
        q, k, v = qkv.transpose(2, 0, 3, 1, 4)
        scores = np.matmul(q * scale, k.transpose(0, 1, 3, 2))
        scores += bias
        scores -= scores.max(-1, keepdims=True)
        np.exp(scores, out=scores)
        scores /= scores.sum(-1, keepdims=True)
        out[a:b] = np.matmul(scores, v).transpose(0, 2, 1, 3).reshape(-1, n, dim)

    for_chunks(n_win, chunk, work, tick)
    return out
