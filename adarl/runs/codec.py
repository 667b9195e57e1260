"""What a checkpoint's arrays.npz and meta.json hold, encoded: pytrees as flat `{path: array}`
and environment states as JSON with their arrays beside them (docs/run-format.md)."""

from __future__ import annotations

import numpy as np

from adarl.errors import UsageError


# ----------------------------------------------------------------------------- pytrees <-> arrays
def flatten_tree(tree, prefix: str = "") -> dict[str, np.ndarray]:
    """Flatten a pytree of arrays into `{path: np.ndarray}` (paths are jax key strings)."""
    import jax

    leaves = jax.tree_util.tree_flatten_with_path(tree)[0]
    return {prefix + jax.tree_util.keystr(path): np.asarray(leaf) for path, leaf in leaves}


def unflatten_tree(template, arrays: dict[str, np.ndarray], prefix: str = ""):
    """Rebuild a pytree shaped like `template` from `flatten_tree` output, checking shapes."""
    import jax

    paths, treedef = jax.tree_util.tree_flatten_with_path(template)
    leaves = []
    for path, leaf in paths:
        key = prefix + jax.tree_util.keystr(path)
        if key not in arrays:
            raise UsageError(
                f"checkpoint is missing array {key!r}; it was written by another version"
            )
        value = arrays[key]
        if tuple(value.shape) != tuple(np.shape(leaf)):
            raise UsageError(
                f"checkpoint array {key!r} has shape {value.shape}, expected {np.shape(leaf)}"
            )
        leaves.append(value)
    return jax.tree_util.tree_unflatten(treedef, leaves)


# ----------------------------------------------------------------------------- environment states
def encode_env_state(obj, arrays: dict, key: str):
    """Make an environment's `get_state()` JSON-able for meta.json: its arrays go to `arrays`
    (the checkpoint's arrays.npz) under `key/…`, exactly, and dicts and tuples keep their kind."""
    if isinstance(obj, np.ndarray):
        arrays[key] = obj
        return {"__array__": key}
    if isinstance(obj, dict):
        return {
            "__dict__": [[k, encode_env_state(v, arrays, f"{key}/{k}")] for k, v in obj.items()]
        }
    if isinstance(obj, list | tuple):
        items = [encode_env_state(v, arrays, f"{key}/{j}") for j, v in enumerate(obj)]
        return {"__tuple__": items} if isinstance(obj, tuple) else items
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def decode_env_state(obj, arrays: dict):
    """The inverse of `encode_env_state`; also reads the SAC loop's run-format-1 encoding
    (arrays inline as `{"__ndarray__": list, "dtype": …}`)."""
    if isinstance(obj, dict):
        if "__array__" in obj:
            return arrays[obj["__array__"]]
        if "__ndarray__" in obj:
            return np.asarray(obj["__ndarray__"], dtype=obj["dtype"])
        if "__dict__" in obj:
            return {k: decode_env_state(v, arrays) for k, v in obj["__dict__"]}
        if "__tuple__" in obj:
            return tuple(decode_env_state(v, arrays) for v in obj["__tuple__"])
        return {k: decode_env_state(v, arrays) for k, v in obj.items()}
    if isinstance(obj, list):
        return [decode_env_state(v, arrays) for v in obj]
    return obj


def encode_env_states(envs, arrays: dict) -> list:
    return [encode_env_state(env.get_state(), arrays, f"env/{i}") for i, env in enumerate(envs)]
