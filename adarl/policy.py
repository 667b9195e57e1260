"""Deterministic policies as plain arrays, runnable with NumPy alone (no JAX).

Every algorithm writes its policy in this format next to each checkpoint
(`checkpoints/step_*/policy_seed_<s>.npz`) through `file_arrays`, the one writer, beside the
one reader `NumpyPolicy`; `adarl export` copies one out and evaluation loads them in worker
processes. Usage::

    from adarl.policy import load
    act = load("policy.npz")
    action = act(obs)              # obs: (obs_dim,) or (batch, obs_dim)

File format (`format = "adarl-policy-1"`), one `.npz`:
    activation            "relu" or "tanh" (after every trunk layer)
    n_layers              number of trunk layers
    l{i}_kind             "dense" | "bottleneck" | "sparse"
      dense:              l{i}_w (in×out), l{i}_b (out)
      bottleneck:         l{i}_w1 (in×r), l{i}_w2 (r×out), l{i}_b (out): x ↦ act(x W1 W2 + b)
      sparse:             l{i}_d (n×n), l{i}_eta, l{i}_lam: one ISTA step, no extra activation,
                          x ↦ ReLU(x + η(Dᵀx − DᵀDx) − ηλ)
    mean_w, mean_b        the action-mean head
    log_std_w, log_std_b  (optional) the log-std head, for `NumpyPolicy.sample` (exploration);
                          the files adarl writes next to checkpoints leave it out
    squash                "tanh": a = c + h·tanh(μ);  "clip": a = clip(μ, low, high)
    action_low/high       action bounds (c, h are their centre and half-range)
    obs_mean/obs_var/obs_clip (optional) observation normalisation: clip((o − m)/√(v + 1e-8), ±clip)
    n_params_full         (optional) parameter count of the same network at full rank
"""

from __future__ import annotations

import os

import numpy as np

FORMAT = "adarl-policy-1"
LOG_STD_MIN, LOG_STD_MAX = -20.0, 2.0  # SAC's clamp of the log-std head


def _activation(name: str):
    if name == "relu":
        return lambda x: np.maximum(x, 0.0)
    if name == "tanh":
        return np.tanh
    raise ValueError(f"unknown activation {name!r}; allowed: relu, tanh")


class NumpyPolicy:
    """A policy read from the arrays of an adarl policy file: deterministic by default, and a
    squashed-Gaussian sampler (`sample`) when the file carries the log-std head."""

    def __init__(self, arrays: dict[str, np.ndarray]):
        fmt = str(arrays.get("format", ""))
        if fmt != FORMAT:
            raise ValueError(f"not an adarl policy (format {fmt!r}, expected {FORMAT!r})")
        a = self.arrays = {k: np.asarray(v) for k, v in arrays.items()}
        self._act = _activation(str(a["activation"]))
        self.n_layers = int(a["n_layers"])
        self.squash = str(a["squash"])
        self.low = np.asarray(a["action_low"], np.float32)
        self.high = np.asarray(a["action_high"], np.float32)
        self._centre, self._half = (self.high + self.low) / 2, (self.high - self.low) / 2
        self._layers = []  # read once: the trainer calls this policy at every environment step
        for i in range(self.n_layers):
            kind = str(a[f"l{i}_kind"])
            if kind == "dense":
                self._layers.append((kind, a[f"l{i}_w"], a[f"l{i}_b"]))
            elif kind == "bottleneck":
                self._layers.append((kind, a[f"l{i}_w1"], a[f"l{i}_w2"], a[f"l{i}_b"]))
            elif kind == "sparse":
                d, eta, lam = a[f"l{i}_d"], float(a[f"l{i}_eta"]), float(a[f"l{i}_lam"])
                self._layers.append((kind, d, eta, lam))
            else:
                raise ValueError(f"unknown layer kind {kind!r} in policy file")

    def features(self, obs: np.ndarray) -> np.ndarray:
        """The trunk's output (after its last activation), read by the heads."""
        a = self.arrays
        x = np.asarray(obs, np.float32)
        if "obs_mean" in a:
            x = (x - a["obs_mean"]) / np.sqrt(a["obs_var"] + 1e-8)
            x = np.clip(x, -a["obs_clip"], a["obs_clip"])
        for kind, *p in self._layers:
            if kind == "dense":
                x = self._act(x @ p[0] + p[1])
            elif kind == "bottleneck":
                x = self._act((x @ p[0]) @ p[1] + p[2])
            else:
                x = sparse_coding_step(x, *p)
        return x

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        mean = self.features(obs) @ self.arrays["mean_w"] + self.arrays["mean_b"]
        return self._bound(mean)

    def sample(self, obs: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """Exploration action a = c + h·tanh(μ + σ·ε) for standard-normal `noise` ε, with
        log σ clamped to [−20, 2] (SAC's squashed Gaussian; needs `log_std_w`/`log_std_b`)."""
        if "log_std_w" not in self.arrays:
            raise ValueError("this policy file has no log-std head; it is deterministic only")
        h = self.features(obs)
        mean = h @ self.arrays["mean_w"] + self.arrays["mean_b"]
        log_std = h @ self.arrays["log_std_w"] + self.arrays["log_std_b"]
        log_std = np.clip(log_std, LOG_STD_MIN, LOG_STD_MAX)
        return self._bound(mean + np.exp(log_std) * noise)

    def _bound(self, u: np.ndarray) -> np.ndarray:
        if self.squash == "tanh":
            return (self._centre + self._half * np.tanh(u)).astype(np.float32)
        return np.clip(u, self.low, self.high).astype(np.float32)

    def n_params(self) -> int:
        """Parameters of the deterministic policy as stored (bottlenecks at their current rank)."""
        skip = {"action_low", "action_high", "obs_mean", "obs_var", "obs_clip", "n_params_full"}
        skip |= {"log_std_w", "log_std_b"}
        return int(
            sum(
                v.size
                for k, v in self.arrays.items()
                if v.dtype.kind == "f" and k not in skip and not k.endswith(("_eta", "_lam"))
            )
        )

    def n_params_full(self) -> int:
        """Parameters of the same policy at full rank: every bottleneck W1·W2 at its configured
        width, which in adarl is the layer's output width (`mlp.make_layout`), whatever rank
        training cut it to. Computed from the shapes, so it holds for every policy file."""
        n = self.n_params()
        for i in range(self.n_layers):
            if str(self.arrays[f"l{i}_kind"]) == "bottleneck":
                w1, w2 = self.arrays[f"l{i}_w1"], self.arrays[f"l{i}_w2"]
                n_in, n_out = w1.shape[0], w2.shape[1]
                n += n_in * n_out + n_out * n_out - w1.size - w2.size
        return n


def sparse_coding_step(x: np.ndarray, d: np.ndarray, eta: float, lam: float) -> np.ndarray:
    """One ISTA step from z₀ = x: ReLU(x + η(Dᵀx − DᵀDx) − ηλ), rows of `x` as samples."""
    return np.maximum(x + eta * (x @ d - (x @ d.T) @ d) - eta * lam, 0.0)


def file_arrays(
    layers: list[tuple],
    mean: tuple,
    low,
    high,
    activation: str,
    *,
    log_std: tuple | None = None,
    obs_norm: tuple | None = None,
    n_params_full: bool = False,
) -> dict[str, np.ndarray]:
    """The arrays of a policy file (the format above); every algorithm's policy is written by
    this function. `layers`: the trunk, each layer as `NumpyPolicy` reads it back,
    ("dense", w, b), ("bottleneck", w1, w2, b) or ("sparse", d, eta, lam); `mean` and `log_std`:
    the heads' (w, b); `obs_norm`: (mean, var, clip) of the observation normaliser; squash
    "tanh"; `n_params_full`: also record the parameter count at full rank."""
    out = {
        "format": np.asarray(FORMAT),
        "activation": np.asarray(activation),
        "n_layers": np.asarray(len(layers)),
        "squash": np.asarray("tanh"),
        "action_low": np.asarray(low, np.float32),
        "action_high": np.asarray(high, np.float32),
    }
    names = {"dense": ("w", "b"), "bottleneck": ("w1", "w2", "b"), "sparse": ("d", "eta", "lam")}
    for i, (kind, *values) in enumerate(layers):
        out[f"l{i}_kind"] = np.asarray(kind)
        out.update({f"l{i}_{n}": np.asarray(v) for n, v in zip(names[kind], values, strict=True)})
    out["mean_w"], out["mean_b"] = np.asarray(mean[0]), np.asarray(mean[1])
    if log_std is not None:
        out["log_std_w"], out["log_std_b"] = np.asarray(log_std[0]), np.asarray(log_std[1])
    if obs_norm is not None:
        out["obs_mean"], out["obs_var"], out["obs_clip"] = (np.asarray(x) for x in obs_norm)
    if n_params_full:
        out["n_params_full"] = np.asarray(NumpyPolicy(out).n_params_full())
    return out


def to_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """The bytes of a policy file (checks that it loads first)."""
    import io

    NumpyPolicy(arrays)
    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(v) for k, v in arrays.items()})
    return buf.getvalue()


def save(path: str | os.PathLike, arrays: dict[str, np.ndarray]) -> None:
    """Write a policy file atomically."""
    from adarl.files import atomic_write_bytes

    atomic_write_bytes(path, to_bytes(arrays))


def load(path: str | os.PathLike) -> NumpyPolicy:
    """Load a policy file written by adarl; returns a callable obs -> action. A file that is
    not one (truncated, bit-flipped, another kind of file) raises a one-line `UsageError`
    naming it."""
    from adarl.errors import UsageError, reason

    try:
        with np.load(path, allow_pickle=False) as z:
            return NumpyPolicy({k: z[k] for k in z.files})
    except FileNotFoundError:
        raise UsageError(f"policy file {path} does not exist") from None
    except Exception as exc:  # BadZipFile, EOFError, ValueError, KeyError, …: all mean damaged
        raise UsageError(
            f"policy file {path} is damaged or not an adarl policy ({reason(exc)})"
        ) from exc
