"""MLPs as plain pytrees: dense layers, AdaRL's linear bottleneck and the sparse-coding layer.

A network is a list of layer dicts plus a static `layout` (a tuple of layer kinds and sizes) that
`jit` treats as a constant. Kinds:

* `("dense", n_in, n_out)`: `{"w": (n_in, n_out), "b": (n_out,)}`
* `("bottleneck", n_in, width, n_out)`: `{"w1": (n_in, width), "w2": (width, n_out), "b": (n_out,)}`,
  i.e. the weight W = W1·W2 with no bias or activation between (paper appendix, Fig. 7). Its
  0/1 rank mask lives outside the parameters (see `adarl.nets.rank`).
* `("sparse", n)`: `{"d": (n, n)}`, one ISTA step of sparse coding (Tiwari et al. reconstruction,
  see docs/algorithms.md); it carries its own ReLU and is not followed by the activation.

An activation follows every dense/bottleneck layer except the last when `final_activation` is
False. Weights are stored (in, out) so a layer is `x @ w + b`.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from adarl.nets.choices import INITS

ACTIVATION_FUNCTIONS = {"relu": jax.nn.relu, "tanh": jnp.tanh}  # one per name in ACTIVATIONS


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


def n_params(layout: tuple) -> int:
    """Number of parameters of a network of `layout` (`init_layers`'s arrays), without building it."""
    sizes = {
        "dense": lambda n_in, n_out: n_in * n_out + n_out,
        "bottleneck": lambda n_in, width, n_out: n_in * width + width * n_out + n_out,
        "sparse": lambda n: n * n,
    }
    return sum(sizes[kind](*dims) for kind, *dims in layout)


def _torch_uniform(rng: np.random.Generator, shape, fan_in):
    """PyTorch nn.Linear default: U(−1/√fan_in, 1/√fan_in) (weights and biases)."""
    bound = 1.0 / np.sqrt(fan_in)
    return rng.uniform(-bound, bound, size=shape).astype(np.float32)


def orthogonal(rng: np.random.Generator, shape, gain):
    """Orthogonal matrix (Saxe et al. 2014; rows or columns orthonormal) times `gain`, as
    torch.nn.init.orthogonal_: Q of the QR of a Gaussian matrix, signs fixed by diag(R)."""
    rows, cols = shape
    a = rng.normal(size=(max(rows, cols), min(rows, cols)))
    q, r = np.linalg.qr(a)
    q *= np.sign(np.diag(r))
    q = q if rows >= cols else q.T
    return (gain * q).astype(np.float32)


def init_layers(
    rng: np.random.Generator,
    layout: tuple,
    init: str = "torch",
    gain: float = 2.0**0.5,
    out_gain: float = 1.0,
    rank: int | None = None,
    has_output_layer: bool = True,
) -> list[dict]:
    """Initialise parameters for `layout` with NumPy (no XLA compilation at start-up).

    `torch`: PyTorch's nn.Linear defaults (what Spinning Up, and so the paper, uses); a bottleneck
    of rank r is nn.Linear(n_in, r, bias=False) then nn.Linear(r, n_out). `orthogonal`:
    orthogonal weights with `gain` on hidden layers and `out_gain` on the output layer (the last
    one, when `has_output_layer`), zero biases (Parseval). Bottleneck components past `rank`
    (default: full width) are exactly zero.
    """
    if init not in INITS:
        raise ValueError(f"unknown init {init!r}; allowed: {', '.join(INITS)}")
    params = []
    last = max(i for i, spec in enumerate(layout) if spec[0] != "sparse")
    for i, spec in enumerate(layout):
        g = out_gain if (has_output_layer and i == last) else gain
        if spec[0] == "dense":
            _, n_in, n_out = spec
            if init == "torch":
                w = _torch_uniform(rng, (n_in, n_out), n_in)
                b = _torch_uniform(rng, (n_out,), n_in)
            else:
                w = orthogonal(rng, (n_in, n_out), g)
                b = np.zeros((n_out,), np.float32)
            params.append({"w": w, "b": b})
        elif spec[0] == "bottleneck":
            _, n_in, width, n_out = spec
            r = width if rank is None else rank
            if init == "torch":
                w1 = _torch_uniform(rng, (n_in, width), n_in)
                w2 = _torch_uniform(rng, (width, n_out), r)
                b = _torch_uniform(rng, (n_out,), r)
            else:  # orthogonal product with the layer's gain, split evenly between the factors
                w1 = orthogonal(rng, (n_in, width), g**0.5)
                w2 = orthogonal(rng, (width, n_out), g**0.5)
                b = np.zeros((n_out,), np.float32)
            keep = (np.arange(width) < r).astype(np.float32)
            params.append({"w1": w1 * keep[None, :], "w2": w2 * keep[:, None], "b": b})
        else:  # sparse-coding dictionary, initialised at the identity: the first step is then a
            _, n = spec  # pure soft threshold, ReLU(x − ηλ), and never denser than its input
            params.append({"d": np.eye(n, dtype=np.float32)})
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
    act = ACTIVATION_FUNCTIONS[activation]
    last = max(i for i, spec in enumerate(layout) if spec[0] != "sparse")
    for i, (spec, p) in enumerate(zip(layout, params)):
        if spec[0] == "sparse":
            x = sparse_coding(x, p["d"], sparse_eta, sparse_lam)
            continue
        if spec[0] == "dense":
            x = x @ p["w"] + p["b"]
        else:
            x = bottleneck_matmul(x, p["w1"], masks[i], p["w2"]) + p["b"]
        if i != last or final_activation:
            x = act(x)
    return x


def bottleneck_matmul(x, w1, mask, w2):
    """x · W1 · diag(mask) · W2, in the cheaper order for these (static) shapes: the product
    W1·W2 first (n_in·d·n_out multiply-adds, once) or x through both factors (batch·d·(n_in +
    n_out)). Both give masked components exactly zero output and zero gradient."""
    n_in, width = w1.shape
    n_out = w2.shape[1]
    batch = math.prod(x.shape[:-1])
    if n_in * width * n_out + batch * n_in * n_out < batch * width * (n_in + n_out):
        return x @ ((w1 * mask) @ w2)
    return ((x @ w1) * mask) @ w2


def sparse_coding(x, d, eta: float, lam: float):
    """One ISTA step for min_z ½‖x − Dz‖² + λ‖z‖₁, z ≥ 0, from z₀ = x:
    z = ReLU(x + η(Dᵀx − DᵀDx) − ηλ) (rows of x are samples)."""
    return jax.nn.relu(x + eta * (x @ d - (x @ d.T) @ d) - eta * lam)


def rank_masks(layout: tuple, rank: int | None = None) -> list:
    """Rank masks keeping the first `rank` (default: all) components of every bottleneck of
    `layout` (None for other layers)."""
    return [
        (np.arange(spec[2]) < (rank or spec[2])).astype(np.float32)
        if spec[0] == "bottleneck"
        else None
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
