"""The AGNDC architecture as one dataclass (nanoGPT's ``GPTConfig`` habit).

Every ablation of the paper is a configuration:

* Table 4, row 1 (UNDC):            ``undc_baseline()``
  = ``AGNDCConfig(levels=0, use_attention=False, use_snake=False, use_dffm=False, use_crpm=False)``
* Table 4, row 2 (+GDFEM) = Table 5, j = 0: ``AGNDCConfig(levels=0)``
* Table 4, row 3 (+DFFM):           ``AGNDCConfig(use_crpm=False)``
* Table 4, row 4 (+CRPM, full):     ``AGNDCConfig()``
* Table 5 (j = 0..3):               ``AGNDCConfig(levels=j)``
* Table 6 (omega = 16..128):        ``AGNDCConfig(width=w)``
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

from ..errors import ModelError


@dataclass(frozen=True)
class AGNDCConfig:
    # omega, feature channels of every AGDRNet (paper Table 6: 64 is best; 16/32/128 tested)
    width: int = 64
    # j, number of 2x down-samplings: scales 0..j, each with its own network (Table 5: j = 2)
    levels: int = 2
    # LWSA window edge in lattice points (Swin3D windows); a power of two so windows tile the
    # cascade's lattices; 4^3 = 64 tokens keeps attention cheap on a CPU
    window: int = 4
    # LWSA attention heads: 2 heads of 16 channels (Swin uses 32 per head; 8 per head runs
    # ~2.5x slower on a CPU for the same width)
    heads: int = 2
    # LWSA works at width // attn_div channels: it only has to produce a 1-channel map A_s
    attn_div: int = 2
    # hidden width of the LWSA feed-forward, as a multiple of its width (Swin uses 4; 2 halves
    # the cost and the map is 1 channel)
    mlp_ratio: int = 2
    # DSConv taps per snake (DSCNet's K = 9): reach of +-4 points along the branch axis
    snake_kernel: int = 9
    # DSConv extend scope: each tap may drift at most this many points from its predecessor
    snake_scope: float = 1.0
    # each DSConv branch (3 snakes + 1 plain) has width // snake_div channels; the branches are
    # fused back to the full width by a 1x1x1 conv (keeps the gathers, the CPU bottleneck, small)
    snake_div: int = 4
    # band evaluation (band_ops.py): features are computed only within this Chebyshev distance
    # of the surface, points farther away take far-field values. Exact when trained that way
    # (forward_band); an approximation for densely trained weights (larger = closer, slower)
    band_radius: int = 4
    # LeakyReLU slope used everywhere; no BatchNorm, so a band of the grid can be evaluated alone
    act_slope: float = 0.1
    # False: GDFEM has no LWSA branch, F^A is just the conv features (no attention map channel)
    use_attention: bool = True
    # False: the three DSConvs of GDFEM become plain 3x3x3 convs (same residual wiring, eq. 14)
    use_snake: bool = True
    # False: W_s = U_s, the sparse up-sampled coarser prediction, unfused (needs levels >= 1)
    use_dffm: bool = True
    # False: P_s = P'_s + W_s instead of CRPM(W_s, P'_s) (needs levels >= 1)
    use_crpm: bool = True
    # True: the finest scale predicts a correction to the surface nets vertex (surfacenets.py),
    # vertex = surface_nets + (network - 0.5); its vertex head starts at zero weights, so an
    # untrained cascade already returns surface nets and training only has to learn what a
    # binary neighbourhood says beyond the mean of the crossed-edge midpoints
    surface_nets_prior: bool = True

    def __post_init__(self) -> None:
        self.validate()

    # ------------------------------------------------------------------ derived sizes
    @property
    def attn_width(self) -> int:
        return self.width // self.attn_div

    @property
    def snake_width(self) -> int:
        return self.width // self.snake_div

    @property
    def scales(self) -> int:
        return self.levels + 1

    # ------------------------------------------------------------------ (de)serialisation
    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> AGNDCConfig:
        """Build a config from a dict (a checkpoint's ``model_config``); unknown keys refused."""
        if not isinstance(data, dict):
            raise ModelError(f"model config must be a mapping, got {type(data).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ModelError(f"unknown model config key(s) {', '.join(unknown)}; "
                             f"known keys: {', '.join(sorted(known))}")
        return cls(**data)

    def validate(self) -> None:
        """Raise ModelError naming the first bad field."""
        for f in fields(self):
            value = getattr(self, f.name)
            want = {"int": int, "float": (int, float), "bool": bool}[str(f.type)]
            ok = isinstance(value, want) and (f.type == "bool" or not isinstance(value, bool))
            if not ok:
                raise ModelError(f"model config {f.name} must be {f.type}, got {value!r}")
        _check(self.width >= 4 and self.width % 4 == 0, "width", self.width,
               "a multiple of 4, at least 4 (the paper uses 16, 32, 64 or 128)")
        _check(0 <= self.levels <= 4, "levels", self.levels, "in 0..4")
        _check(self.window >= 2 and _pow2(self.window), "window", self.window,
               "a power of two >= 2")
        _check(self.heads >= 1, "heads", self.heads, ">= 1")
        _check(self.attn_div >= 1 and self.width % self.attn_div == 0, "attn_div",
               self.attn_div, "a divisor of width")
        _check(self.attn_width % self.heads == 0, "heads", self.heads,
               f"a divisor of the attention width {self.attn_width}")
        _check(self.mlp_ratio >= 1, "mlp_ratio", self.mlp_ratio, ">= 1")
        _check(self.snake_kernel >= 3 and self.snake_kernel % 2 == 1, "snake_kernel",
               self.snake_kernel, "odd and >= 3")
        _check(0.0 < self.snake_scope <= 4.0, "snake_scope", self.snake_scope, "in (0, 4]")
        _check(self.snake_div >= 1 and self.width % self.snake_div == 0, "snake_div",
               self.snake_div, "a divisor of width")
        _check(1 <= self.band_radius <= 64, "band_radius", self.band_radius, "in 1..64")
        _check(0.0 <= self.act_slope < 1.0, "act_slope", self.act_slope, "in [0, 1)")


def _pow2(n: int) -> bool:
    return n > 0 and n & (n - 1) == 0


def _check(ok: bool, name: str, value, want: str) -> None:
    if not ok:
        raise ModelError(f"model config {name}={value!r} is invalid: must be {want}")


# the fields the paper's ablations (Tables 4-5) switch; a variant differs from AGNDC only here
ABLATION_KEYS = ("levels", "use_attention", "use_snake", "use_dffm", "use_crpm")


def undc_baseline(width: int = 64) -> AGNDCConfig:
    """Paper Table 4, first row: one scale, plain 3x3x3 convs, no attention, no fusion."""
    return AGNDCConfig(width=width, levels=0, use_attention=False, use_snake=False,
                       use_dffm=False, use_crpm=False)
