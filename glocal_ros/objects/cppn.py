"""Random CPPN-like implicit fields that define the generated solids.

EGAD evolved CPPNs (small networks over voxel coordinates and radii with
sin/gauss/sigmoid/identity nodes) and thresholded their output. Here each
candidate is one random network instead of an evolved one; a scalar
``complexity_knob`` in [0, 1] controls depth, frequency and how strongly the
network perturbs a base superellipsoid, so that knob 0 gives a plain
ellipsoid or rounded box and knob 1 gives the busy, lobed shapes of EGAD's
high-complexity columns. The measured complexity, not the knob, places an
object on the grid.

The envelope sets the base solid's proportions. ``blob`` keeps every
semi-axis within [0.35, 0.65] (aspect ratios under 1.9: what EGAD's
generated objects mostly look like). ``wide`` adds what a top-down parallel
gripper finds hard and EGAD's blobs never are: thirds of the candidates are
blobs, slabs (one semi-axis 0.07..0.2, so flat objects that must be gripped
low or at an edge) and rods (two semi-axes 0.1..0.25), and every one of them
tapers along its long axis (``taper``: one end down to a quarter of the
other's cross-section), which makes wedges, cones and heads away from the
centre of mass.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Sequence

import numpy as np
from scipy import ndimage

ACTIVATIONS: tuple[str, ...] = ("sin", "gauss", "tanh", "abs")

# The solid lives well inside this cube so that the field is negative on the
# grid border and marching cubes always yields a closed surface.
DOMAIN_HALF_WIDTH = 1.35
_MIN_SEMI_AXIS = 0.35
_MAX_SEMI_AXIS = 0.65
# With r >= 1.35 / 0.65 on the border, amplitude < 1.07 keeps the field negative there. A taper only
# shrinks semi-axes, so it keeps that bound.
_MAX_AMPLITUDE = 1.0
ENVELOPES: tuple[str, ...] = ("blob", "wide")
_SLAB_SEMI_AXIS = (0.07, 0.2)
_ROD_SEMI_AXIS = (0.1, 0.25)
_MAX_TAPER = 0.6


@dataclass(frozen=True)
class CPPNParams:
    """A sampled field: superellipsoid base plus a random network perturbation.

    The field is ``(1 - r) + amplitude * tanh(net(x, y, z, r))`` where ``r``
    is the superellipsoid radius ``(|x/a|^p + |y/b|^p + |z/c|^p)^(1/p)``; the
    solid is where the field is positive. Every layer sees the previous
    layer and the raw inputs, as CPPN hidden nodes can connect to inputs.
    """

    complexity_knob: float
    semi_axes: tuple[float, float, float]
    exponent: float
    amplitude: float
    weights: tuple[tuple[tuple[float, ...], ...], ...]
    biases: tuple[tuple[float, ...], ...]
    activations: tuple[tuple[str, ...], ...]
    output_weights: tuple[float, ...]
    output_bias: float
    taper: float = 0.0
    """Cross-sections along x scale by ``(1 + taper * x / a) / (1 + |taper|)`` (0: no taper)."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready parameters (lists instead of tuples)."""
        return _listify(asdict(self))


def _listify(value: Any) -> Any:
    if isinstance(value, dict):
        return {key: _listify(item) for key, item in value.items()}
    if isinstance(value, (tuple, list)):
        return [_listify(item) for item in value]
    return value


def sample_cppn(rng: np.random.Generator, complexity_knob: float, envelope: str = "blob") -> CPPNParams:
    """Draw a random field whose structural richness grows with ``complexity_knob``, its base solid's
    proportions from ``envelope`` (see the module's docstring)."""
    check_envelope(envelope)
    k = float(np.clip(complexity_knob, 0.0, 1.0))
    semi_axes, taper = _base_proportions(rng, envelope)
    # p = 2 is an ellipsoid; larger p tends to a box, so simple shapes cover both.
    exponent = float(rng.choice([2.0, 2.0, 3.0, 4.0, 6.0, 8.0]))
    amplitude = float(_MAX_AMPLITUDE * k * rng.uniform(0.6, 1.0))
    n_layers = int(round(k * 3.0))
    width = int(rng.integers(2, 3 + round(4 * k)))
    # Larger weights mean higher spatial frequencies: more ridges and lobes.
    # Capped so the top end gives lobes and holes rather than surface noise.
    weight_scale = 0.6 + 1.6 * k

    weights, biases, activations = [], [], []
    fan_in = 4
    for _ in range(n_layers):
        weights.append(_round(rng.normal(0.0, weight_scale, size=(width, fan_in))))
        biases.append(_round(rng.normal(0.0, 1.0, size=width)))
        activations.append(tuple(str(a) for a in rng.choice(ACTIVATIONS, size=width)))
        fan_in = width + 4
    raw_out = rng.normal(0.0, 1.0, size=fan_in)

    # Standardise the network output over the body region of a fixed grid, so
    # ``amplitude`` really sets the perturbation size: an unnormalised random
    # network is often saturated or flat, leaving a plain blob at any knob.
    axis = np.linspace(-DOMAIN_HALF_WIDTH, DOMAIN_HALF_WIDTH, 20)
    inputs = _inputs(np.meshgrid(axis, axis, axis, indexing="ij"), semi_axes, exponent, taper)
    inputs = inputs[inputs[:, 3] <= 1.0 + amplitude]
    net = _hidden(weights, biases, activations, inputs) @ raw_out
    gain = float(rng.uniform(1.0, 1.5))
    std = float(net.std()) or 1.0
    output_weights = _round(raw_out * gain / std)
    return CPPNParams(
        complexity_knob=k,
        semi_axes=semi_axes,  # type: ignore[arg-type]
        exponent=exponent,
        amplitude=amplitude,
        weights=tuple(tuple(tuple(row) for row in w) for w in weights),
        biases=tuple(tuple(b) for b in biases),
        activations=tuple(activations),
        output_weights=tuple(output_weights),
        output_bias=round(float(-net.mean() * gain / std + rng.normal(0.0, 0.3)), 6),
        taper=taper,
    )


def check_envelope(envelope: str) -> None:
    """``ValueError`` naming the envelopes, unless ``envelope`` is one."""
    if envelope not in ENVELOPES:
        raise ValueError(f"unknown envelope {envelope!r}: choose one of {', '.join(ENVELOPES)}")


def _base_proportions(rng: np.random.Generator, envelope: str) -> tuple[tuple[float, float, float], float]:
    """Semi-axes and taper of the base solid. ``blob`` draws exactly what the generator drew before
    envelopes existed, so a seed still gives the same blob set."""
    if envelope == "blob":
        return tuple(float(v) for v in rng.uniform(_MIN_SEMI_AXIS, _MAX_SEMI_AXIS, size=3)), 0.0  # type: ignore
    form = rng.integers(3)  # 0 blob, 1 slab, 2 rod
    axes = rng.uniform(_MIN_SEMI_AXIS, _MAX_SEMI_AXIS, size=3)
    axes[0] = _MAX_SEMI_AXIS  # the long axis, along which the taper runs
    if form == 1:
        axes[2] = rng.uniform(*_SLAB_SEMI_AXIS)
    elif form == 2:
        axes[1:] = rng.uniform(*_ROD_SEMI_AXIS, size=2)
    taper = round(float(rng.uniform(-_MAX_TAPER, _MAX_TAPER)), 6)
    return tuple(round(float(v), 6) for v in axes), taper  # type: ignore[return-value]


def _round(values: np.ndarray) -> list:
    # Rounded so the JSON metadata reproduces the field exactly.
    return np.round(values, 6).tolist()


def _activate(name: str, x: np.ndarray) -> np.ndarray:
    if name == "sin":
        return np.sin(x)
    if name == "gauss":
        return np.exp(-(x**2))
    if name == "tanh":
        return np.tanh(x)
    if name == "abs":
        return np.abs(x)
    raise ValueError(f"unknown activation {name!r}")


def _inputs(grid: list[np.ndarray], semi_axes: Sequence[float], exponent: float, taper: float = 0.0) -> np.ndarray:
    """(N, 4) network inputs x, y, z and the (tapered) superellipsoid radius r."""
    x, y, z = (g.ravel() for g in grid)
    a, b, c = semi_axes
    if taper:
        section = (1.0 + taper * np.clip(x / a, -1.0, 1.0)) / (1.0 + abs(taper))
        b, c = b * section, c * section
    r = (np.abs(x / a) ** exponent + np.abs(y / b) ** exponent + np.abs(z / c) ** exponent) ** (1.0 / exponent)
    return np.stack([x, y, z, r], axis=1)


def _hidden(weights: Sequence, biases: Sequence, activations: Sequence, inputs: np.ndarray) -> np.ndarray:
    """Last hidden layer, concatenated with the raw inputs (the output layer's input)."""
    hidden = inputs
    for w, bias, acts in zip(weights, biases, activations):
        pre = hidden @ np.asarray(w).T + np.asarray(bias)
        post = np.empty_like(pre)
        for j, name in enumerate(acts):
            post[:, j] = _activate(name, pre[:, j])
        hidden = np.concatenate([post, inputs], axis=1)
    return hidden


def evaluate_field(
    params: CPPNParams,
    resolution: int,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Sample the field on a grid with ``resolution`` points along its longest side.

    The box ``[lower, upper]`` defaults to the whole domain cube; spacing is
    equal on all axes. Sampling a tight box around the solid gives every
    object the same number of samples across its longest extent, which keeps
    tessellation density, and so the complexity metric, comparable.

    Returns the field values (positive inside the solid) and the grid spacing
    in domain units.
    """
    lo = np.full(3, -DOMAIN_HALF_WIDTH) if lower is None else np.asarray(lower, dtype=float)
    hi = np.full(3, DOMAIN_HALF_WIDTH) if upper is None else np.asarray(upper, dtype=float)
    spacing = float((hi - lo).max()) / (resolution - 1)
    axes = [lo[i] + spacing * np.arange(int(np.ceil((hi[i] - lo[i]) / spacing - 1e-9)) + 1) for i in range(3)]
    grid = np.meshgrid(*axes, indexing="ij")
    inputs = _inputs(grid, params.semi_axes, params.exponent, params.taper)
    hidden = _hidden(params.weights, params.biases, params.activations, inputs)
    out = np.tanh(hidden @ np.asarray(params.output_weights) + params.output_bias)
    field = (1.0 - inputs[:, 3]) + params.amplitude * out
    return field.reshape(grid[0].shape), spacing


def solid_bounds(params: CPPNParams, resolution: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Domain-space box around the field's largest solid component (coarse pass).

    Padded by two coarse cells so thin parts missed at this resolution still
    fit inside the fine grid.
    """
    field, spacing = evaluate_field(params, resolution)
    labels, count = ndimage.label(field > 0.0)
    if count == 0:
        return np.full(3, -DOMAIN_HALF_WIDTH), np.full(3, DOMAIN_HALF_WIDTH)
    largest = int(np.argmax(np.bincount(labels.ravel())[1:])) + 1
    idx = np.argwhere(labels == largest)
    lo = -DOMAIN_HALF_WIDTH + spacing * (idx.min(axis=0) - 2)
    hi = -DOMAIN_HALF_WIDTH + spacing * (idx.max(axis=0) + 2)
    return np.maximum(lo, -DOMAIN_HALF_WIDTH), np.minimum(hi, DOMAIN_HALF_WIDTH)
