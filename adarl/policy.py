"""Deterministic policies as plain arrays, runnable with NumPy alone (no JAX).

Every algorithm writes its policy in this format next to each checkpoint
(`checkpoints/step_*/policy_seed_<s>.npz`); `adarl export` copies one out and evaluation loads
them in worker processes. Usage::

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
    squash                "tanh": a = c + h·tanh(μ);  "clip": a = clip(μ, low, high)
    action_low/high       action bounds (c, h are their centre and half-range)
    obs_mean/obs_var/obs_clip (optional) observation normalisation: clip((o − m)/√(v + 1e-8), ±clip)
    n_params_full         (optional) parameter count of the same network at full rank
"""

from __future__ import annotations

import os

import numpy as np

FORMAT = "adarl-policy-1"


def _activation(name: str):
    if name == "relu":
        return lambda x: np.maximum(x, 0.0)
    if name == "tanh":
        return np.tanh
    raise ValueError(f"unknown activation {name!r}; allowed: relu, tanh")


class NumpyPolicy:
    """A deterministic policy read from the arrays of an adarl policy file."""

    def __init__(self, arrays: dict[str, np.ndarray]):
        fmt = str(arrays.get("format", ""))
        if fmt != FORMAT:
            raise ValueError(f"not an adarl policy (format {fmt!r}, expected {FORMAT!r})")
        self.arrays = {k: np.asarray(v) for k, v in arrays.items()}
        self._act = _activation(str(arrays["activation"]))
        self.n_layers = int(arrays["n_layers"])
        self.squash = str(arrays["squash"])
        self.low = np.asarray(arrays["action_low"], np.float32)
        self.high = np.asarray(arrays["action_high"], np.float32)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        a = self.arrays
        x = np.asarray(obs, np.float32)
        if "obs_mean" in a:
            x = (x - a["obs_mean"]) / np.sqrt(a["obs_var"] + 1e-8)
            x = np.clip(x, -a["obs_clip"], a["obs_clip"])
        for i in range(self.n_layers):
            kind = str(a[f"l{i}_kind"])
            if kind == "dense":
                x = self._act(x @ a[f"l{i}_w"] + a[f"l{i}_b"])
            elif kind == "bottleneck":
                x = self._act((x @ a[f"l{i}_w1"]) @ a[f"l{i}_w2"] + a[f"l{i}_b"])
            elif kind == "sparse":
                x = sparse_coding_step(
                    x, a[f"l{i}_d"], float(a[f"l{i}_eta"]), float(a[f"l{i}_lam"])
                )
            else:
                raise ValueError(f"unknown layer kind {kind!r} in policy file")
        mean = x @ a["mean_w"] + a["mean_b"]
        if self.squash == "tanh":
            centre, half = (self.high + self.low) / 2, (self.high - self.low) / 2
            return (centre + half * np.tanh(mean)).astype(np.float32)
        return np.clip(mean, self.low, self.high).astype(np.float32)

    def n_params(self) -> int:
        """Parameters of the deterministic policy as stored (bottlenecks at their current rank)."""
        skip = {"action_low", "action_high", "obs_mean", "obs_var", "obs_clip", "n_params_full"}
        return int(
            sum(
                v.size
                for k, v in self.arrays.items()
                if v.dtype.kind == "f" and k not in skip and not k.endswith(("_eta", "_lam"))
            )
        )


def sparse_coding_step(x: np.ndarray, d: np.ndarray, eta: float, lam: float) -> np.ndarray:
    """One ISTA step from z₀ = x: ReLU(x + η(Dᵀx − DᵀDx) − ηλ), rows of `x` as samples."""
    return np.maximum(x + eta * (x @ d - (x @ d.T) @ d) - eta * lam, 0.0)


def to_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """The bytes of a policy file (checks that it loads first)."""
    import io

    NumpyPolicy(arrays)
    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(v) for k, v in arrays.items()})
    return buf.getvalue()


def save(path: str | os.PathLike, arrays: dict[str, np.ndarray]) -> None:
    """Write a policy file atomically."""
    from adarl.train.io import atomic_write_bytes

    atomic_write_bytes(path, to_bytes(arrays))


def load(path: str | os.PathLike) -> NumpyPolicy:
    """Load a policy file written by adarl; returns a callable obs -> action."""
    with np.load(path, allow_pickle=False) as z:
        return NumpyPolicy({k: z[k] for k in z.files})
