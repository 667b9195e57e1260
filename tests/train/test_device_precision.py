"""The device backend's matmul precision (`adarl.device.MATMUL_PRECISION`, float32) on CPU: set
explicitly in the physics and in every function of the device learner (its chunk, truncation,
evaluation), whatever the process's default; recorded in checkpoints; and a chunk and a
truncation give the same returns and ranks, to the bit, when every matmul below float32 is
computed as a GPU computes it by default (TF32, emulated here: XLA's CPU backend ignores the
precision, so a GPU's rounding is applied to the operands of every matmul traced at a lower
precision). A compile of the device chunk takes 30-130 s on these CPUs: one tiny config."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from adarl.algos import registry
from adarl.device import missing_reason
from adarl.errors import UsageError

pytestmark = [
    pytest.mark.skipif(missing_reason() is not None, reason=str(missing_reason())),
    pytest.mark.slow,
]

BUDGET = {
    "backend": "device",
    "task": "hopper",
    "dynamics": "default",
    "seeds": (0, 1),
    "hidden": (16, 16),
    "total_steps": 1_000,
    "update_every": 10,
    "start_steps": 10,
    "update_after": 10,
    "truncate_every": 20,
    "warmup_steps": 5,
    "log_every": 100,
    "eval_every": 100,
    "checkpoint_every": 100,
    "buffer_size": 200,
    "batch_size": 16,
    "retain_samples": 16,
    "max_episode_steps": 8,
}
GPU_DEFAULT = "tensorfloat32"  # what JAX computes float32 matmuls at on an NVIDIA GPU, unset


def tf32(x):
    """`x` rounded to TF32 (10 mantissa bits, to nearest even), as a GPU's tensor cores read a
    float32 matmul operand."""
    if x.dtype != jnp.float32:
        return x
    bits = jax.lax.bitcast_convert_type(x, jnp.uint32)
    bits = (bits + jnp.uint32(0xFFF) + ((bits >> 13) & jnp.uint32(1))) & jnp.uint32(0xFFFFE000)
    return jax.lax.bitcast_convert_type(bits, jnp.float32)


@pytest.fixture
def gpu_matmuls(monkeypatch):
    """From here on every matmul traced at less than float32 (HIGHEST) has its operands rounded
    to TF32, as on a GPU; the process default is the GPU's; caches cleared so that every
    function is traced anew."""
    from jax._src.lax import lax as lax_internal

    primitive = lax_internal.dot_general_p
    original = primitive.bind

    def bind(lhs, rhs, **params):
        precision = params.get("precision")
        full = isinstance(precision, tuple) and all(
            p == jax.lax.Precision.HIGHEST for p in precision
        )
        if not full:
            lhs, rhs = tf32(lhs), tf32(rhs)
        return original(lhs, rhs, **params)

    monkeypatch.setattr(primitive, "bind", bind, raising=False)
    jax.clear_caches()
    with jax.default_matmul_precision(GPU_DEFAULT):
        yield
    jax.clear_caches()


@pytest.fixture(scope="module")
def config():
    return registry.resolve_config("adarl", "smoke", BUDGET)


def run(config) -> dict:
    """A fresh learner's first 40 steps (4 chunks, 3 of them updating), a truncation, then one
    more chunk: every episode, the truncation's rows and the final state's arrays."""
    from adarl.train.device_learner import DeviceSACLearner

    learner = DeviceSACLearner(config)
    learner.fresh()
    step, episodes = 0, []
    while step < 40:
        advance = learner.advance(step)
        step = advance.step
        episodes += [(e.index, e.step, e.ret, e.length) for e in advance.episodes]
    rows = learner.truncate(step).rows
    advance = learner.advance(step)
    episodes += [(e.index, e.step, e.ret, e.length) for e in advance.episodes]
    state = jax.tree_util.tree_leaves(jax.device_get(learner.state))
    return {"episodes": episodes, "truncation": rows, "state": state, "learner": learner}


@pytest.fixture(scope="module")
def reference(config):
    return run(config)


def test_the_emulation_rounds_what_a_gpu_rounds(gpu_matmuls):
    """The emulation has teeth: a matmul at the GPU's default, vmapped, differentiated, differs
    from float32; at `MATMUL_PRECISION` it does not."""
    from adarl.device import matmul_precision

    rng = np.random.default_rng(0)
    a, b = (rng.normal(size=(3, 32, 32)).astype(np.float32) for _ in range(2))

    def loss(a, b):
        return jnp.sum(jax.vmap(jnp.matmul)(a, b) ** 2)

    exact = np.einsum("kij,kjl->kil", a.astype(np.float64), b.astype(np.float64))
    lowered = np.asarray(jax.jit(jax.vmap(jnp.matmul))(a, b))
    assert np.abs(lowered - exact).max() > 1e-3
    with matmul_precision():
        full = np.asarray(jax.jit(jax.vmap(jnp.matmul))(a, b))
        grad_full = np.asarray(jax.jit(jax.grad(loss))(a, b))
    assert np.abs(full - exact).max() < 1e-4
    assert not np.array_equal(np.asarray(jax.jit(jax.grad(loss))(a, b)), grad_full)


def test_returns_and_ranks_are_the_same_under_a_gpus_matmuls(config, reference, gpu_matmuls):
    """The same run with TF32 emulated for every matmul below float32: the same episodes'
    returns, the same truncation (ranks, spectra) and the same final arrays, bit for bit."""
    again = run(config)
    assert len(reference["episodes"]) > 4
    assert again["episodes"] == reference["episodes"]
    np.testing.assert_equal(again["truncation"], reference["truncation"])  # NaN errors equal
    assert {r["new_rank"] for r in reference["truncation"]} != {16}  # the cut cut something
    assert len(again["state"]) == len(reference["state"])
    for x, y in zip(again["state"], reference["state"], strict=True):
        np.testing.assert_array_equal(x, y)


def _dot_precisions(text: str) -> set[str]:
    return set(re.findall(r"stablehlo\.dot_general.*?precision = \[(\w+), \w+\]", text))


def test_every_matmul_of_the_device_learner_and_the_physics_is_float32(config, reference):
    """Lowered under a process default of TF32, the chunk (physics and updates), the truncation
    (its SVD input), the device evaluation and the task's own step and reset hold only
    float32 (HIGHEST) matmuls."""
    from adarl.train.device_learner import device_task

    learner = reference["learner"]
    fns = learner.fns
    state = jax.eval_shape(lambda: learner.state)
    env = jax.eval_shape(lambda: learner.env)
    task = device_task("hopper", "default", config.device_solver)
    keys = jax.random.split(jax.random.key(0), 2)
    actor, masks = learner.state["actor"], learner.state["masks"]["actor"]
    with jax.default_matmul_precision(GPU_DEFAULT):
        texts = {
            "chunk": fns.chunk.lower(10, state, env, {}, np.int32(0), np.bool_(True)),
            "truncate": fns.truncate.lower(state),
            "evaluate": fns.evaluations["nominal"].lower(actor, masks, learner.eval_keys, {}),
            "step": jax.jit(jax.vmap(task.step)).lower(
                jax.eval_shape(jax.vmap(task.reset), keys), jnp.zeros((2, 3))
            ),
            "reset": jax.jit(jax.vmap(task.reset)).lower(keys),
        }
    for name, lowered in texts.items():
        assert _dot_precisions(lowered.as_text()) == {"HIGHEST"}, name
    # and the control: the same jnp code at the process default lowers to TF32 (HIGH)
    with jax.default_matmul_precision(GPU_DEFAULT):
        plain = jax.jit(lambda a: a @ a).lower(jnp.ones((4, 4))).as_text()
    assert _dot_precisions(plain) == {"HIGH"}


def test_checkpoints_record_the_precision_and_refuse_another(reference):
    learner = reference["learner"]
    arrays, meta = learner.checkpoint_state()
    assert meta == {"backend": "device", "matmul_precision": "highest"}
    assert not hasattr(learner, "envs") and not hasattr(learner, "rngs")  # no host stand-ins
    with pytest.raises(UsageError, match="written with matmul precision 'tensorfloat32'"):
        learner.restore(arrays, {"backend": "device", "matmul_precision": "tensorfloat32"})


def test_the_buffer_leaves_the_device_one_seed_at_a_time(reference):
    """A checkpoint's replay rows are one part per seed (`SeedRows`), read when written, and
    together the rows written so far."""
    from adarl.runs import npz

    learner = reference["learner"]
    arrays, _ = learner.checkpoint_state()
    buffer = jax.device_get(learner.state["buffer"])
    used = int(buffer["size"].max()) + 1
    for key in ("obs", "act", "rew", "term", "valid"):
        stacked = arrays[f"buffer/{key}"]
        assert isinstance(stacked, npz.Stacked) and len(stacked.parts) == learner.n, key
        assert all(p.shape[0] == 1 for p in stacked.parts), key
        np.testing.assert_array_equal(np.asarray(stacked), buffer[key][:, :used], key)
