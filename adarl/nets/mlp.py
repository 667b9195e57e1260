"""MLPs as plain pytrees: dense layers, AdaRL's linear bottleneck and the sparse-coding layer.

A network is a list of layer dicts plus a static `layout` (a tuple of layer kinds and sizes) that
`jit` treats as a constant. Kinds:

* `("dense", n_in, n_out)`: `{"w": (n_in, n_out), "b": (n_out,)}`
* `("bottleneck", n_in, width, n_out)`: `{"w1": (n_in, width), "w2": (width, n_out), "b": (n_out,)}`,
  i.e. the weight W = W1·W2 with no bias or activation between (paper appendix, Fig. 7). Its
  0/1 rank mask lives outside the parameters (see `adarl.nets.rank`).
* `("sparse", n)`: `{"d": (n, n)}`, one ISTA step of sparse coding (Tiwari et al. reconstruction,
  see docs/baselines.md); it carries its own ReLU and is not followed by the activation.

An activation follows every dense/bottleneck layer except the last when `final_activation` is
False. Weights are stored (in, out) so a layer is `x @ w + b`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

ACTIVATIONS = {"relu": jax.nn.relu, "tanh": jnp.tanh}
INITS = ("torch", "orthogonal")


def make_layout(
    sizes: list[int],
    bottlenecks: tuple[int, ...] = (),
    width: int | None = None,
    sparse_after: int | None = None,
) -> tuple:
    """Layout for an MLP through `sizes` (input, hidden…, output).

    `bottlenecks` lists indices of layers (0-based: layer i maps sizes[i] -> sizes[i+1]) to
    factorise; their inner width is `width` (default: that layer's output size). `sparse_after`
    inserts a sparse-coding layer after layer index `sparse_after`.
    """
    layout = []
    n_layers = len(sizes) - 1
    for i in range(n_layers):
        if i in bottlenecks:
            layout.append(("bottleneck", sizes[i], width or sizes[i + 1], sizes[i + 1]))
        else:
            layout.append(("dense", sizes[i], sizes[i + 1]))
        if sparse_after is not None and i == sparse_after:
            layout.append(("sparse", sizes[i + 1]))
    bad = [i for i in bottlenecks if not 0 <= i < n_layers]
    if bad:
        raise ValueError(f"bottleneck layer {bad[0]} does not exist; layers are 0..{n_layers - 1}")
    return tuple(layout)


def _torch_uniform(key, shape, fan_in, dtype):
    """PyTorch nn.Linear default: U(−1/√fan_in, 1/√fan_in) (weights and biases)."""
    bound = 1.0 / jnp.sqrt(fan_in)
    return jax.random.uniform(key, shape, dtype, -bound, bound)


def init_layers(
    key,
    layout: tuple,
    init: str = "torch",
    gain: float = 2.0**0.5,
    out_gain: float = 1.0,
    rank: int | None = None,
    has_output_layer: bool = True,
    dtype=jnp.float32,
) -> list[dict]:
    """Initialise parameters for `layout`.

    `torch`: PyTorch's nn.Linear defaults (what Spinning Up, and so the paper, uses); a bottleneck
    of rank r is nn.Linear(n_in, r, bias=False) then nn.Linear(r, n_out). `orthogonal`:
    orthogonal weights with `gain` on hidden layers and `out_gain` on the output layer (the last
    one, when `has_output_layer`), zero biases (Parseval). Bottleneck components past `rank`
    (default: full width) are exactly zero.
    """
    if init not in INITS:
        raise ValueError(f"unknown init {init!r}; allowed: {', '.join(INITS)}")
    params = []
    keys = jax.random.split(key, len(layout))
    last = max(i for i, spec in enumerate(layout) if spec[0] != "sparse")
    for i, (spec, k) in enumerate(zip(layout, keys)):
        k1, k2, k3 = jax.random.split(k, 3)
        g = out_gain if (has_output_layer and i == last) else gain
        if spec[0] == "dense":
            _, n_in, n_out = spec
            if init == "torch":
                w = _torch_uniform(k1, (n_in, n_out), n_in, dtype)
                b = _torch_uniform(k2, (n_out,), n_in, dtype)
            else:
                w = jax.nn.initializers.orthogonal(g)(k1, (n_in, n_out), dtype)
                b = jnp.zeros((n_out,), dtype)
            params.append({"w": w, "b": b})
        elif spec[0] == "bottleneck":
            _, n_in, width, n_out = spec
            r = width if rank is None else rank
            if init == "torch":
                w1 = _torch_uniform(k1, (n_in, width), n_in, dtype)
                w2 = _torch_uniform(k2, (width, n_out), r, dtype)
                b = _torch_uniform(k3, (n_out,), r, dtype)
            else:  # orthogonal product with the layer's gain, split evenly between the factors
                w1 = jax.nn.initializers.orthogonal(g**0.5)(k1, (n_in, width), dtype)
                w2 = jax.nn.initializers.orthogonal(g**0.5)(k2, (width, n_out), dtype)
                b = jnp.zeros((n_out,), dtype)
            keep = (jnp.arange(width) < r).astype(dtype)
            params.append({"w1": w1 * keep[None, :], "w2": w2 * keep[:, None], "b": b})
        else:  # sparse-coding dictionary, initialised at the identity: the first step is then a
            _, n = spec  # pure soft threshold, ReLU(x − ηλ), and never denser than its input
            params.append({"d": jnp.eye(n, dtype=dtype)})
    return params


def apply_layers(
    params: list[dict],
    masks: list,
    x: jnp.ndarray,
    layout: tuple,
    activation: str = "relu",
    final_activation: bool = False,
    sparse_eta: float = 0.1,
    sparse_lam: float = 0.1,
) -> jnp.ndarray:
    """Forward pass. `masks[i]` is the rank mask of layer i if it is a bottleneck (else None)."""
    act = ACTIVATIONS[activation]
    last = max(i for i, spec in enumerate(layout) if spec[0] != "sparse")
    for i, (spec, p) in enumerate(zip(layout, params)):
        if spec[0] == "sparse":
            x = sparse_coding(x, p["d"], sparse_eta, sparse_lam)
            continue
        if spec[0] == "dense":
            x = x @ p["w"] + p["b"]
        else:
            x = ((x @ p["w1"]) * masks[i]) @ p["w2"] + p["b"]
        if i != last or final_activation:
            x = act(x)
    return x


def sparse_coding(x, d, eta: float, lam: float):
    """One ISTA step for min_z ½‖x − Dz‖² + λ‖z‖₁, z ≥ 0, from z₀ = x:
    z = ReLU(x + η(Dᵀx − DᵀDx) − ηλ) (rows of x are samples)."""
    return jax.nn.relu(x + eta * (x @ d - (x @ d.T) @ d) - eta * lam)


def full_masks(layout: tuple, dtype=jnp.float32) -> list:
    """Rank masks at full width for every bottleneck of `layout` (None elsewhere)."""
    return [jnp.ones((spec[2],), dtype) if spec[0] == "bottleneck" else None for spec in layout]


def fixed_rank_masks(layout: tuple, rank: int, dtype=jnp.float32) -> list:
    """Rank masks keeping the first `rank` components of every bottleneck."""
    return [
        (jnp.arange(spec[2]) < rank).astype(dtype) if spec[0] == "bottleneck" else None
        for spec in layout
    ]


def hidden_weights(params: list[dict], layout: tuple, has_output_layer: bool) -> list[jnp.ndarray]:
    """Weight matrices of the hidden layers (bottleneck: the product W1·W2); the last layer is
    left out when it is the network's output layer (a critic), not when the network is a trunk
    followed by heads (the actor)."""
    last = max(i for i, spec in enumerate(layout) if spec[0] != "sparse")
    out = []
    for i, (spec, p) in enumerate(zip(layout, params)):
        if (has_output_layer and i == last) or spec[0] == "sparse":
            continue
        out.append(p["w"] if spec[0] == "dense" else p["w1"] @ p["w2"])
    return out
