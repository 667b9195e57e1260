"""AdaRL's rank adaptation in a pure-JAX training step (no framework): a regression MLP whose
hidden layer is a factorised W1·W2, cut every d_t steps by `adarl.lowrank.truncate` with the
optimiser reset and the learning rate warming up again after each cut. Run:
    python examples/lowrank_pure_jax.py [steps]
"""

import sys

import jax
import jax.numpy as jnp
import optax

from adarl import lowrank

STEPS = int(sys.argv[1]) if len(sys.argv) > 1 else 3000
CUT_EVERY, WIDTH = 500, 64  # d_t and the bottleneck's stored width

key = jax.random.PRNGKey(0)
k_in, k_mid, k_out, k_x, k_t = jax.random.split(key, 5)
params = {
    "inp": {"w": jax.random.normal(k_in, (8, 64)) / 8**0.5, "b": jnp.zeros(64)},
    "mid": lowrank.init_factorised(k_mid, 64, 64, rank=WIDTH, width=WIDTH),  # masked: one shape
    "out": {"w": jax.random.normal(k_out, (64, 1)) / 8.0, "b": jnp.zeros(1)},
}
x = jax.random.normal(k_x, (1024, 8))
y = jnp.sin(x @ jax.random.normal(k_t, (8, 3))).sum(-1, keepdims=True)  # a rank-3 target


def net(p, x):
    h = jax.nn.relu(x @ p["inp"]["w"] + p["inp"]["b"])
    h = jax.nn.relu(lowrank.apply_factorised(p["mid"], h))
    return h @ p["out"]["w"] + p["out"]["b"]


adam = optax.scale_by_adam()
lr = lowrank.envelope_schedule(1e-3, total_steps=STEPS, warmup_steps=100, cut_every=CUT_EVERY)


@jax.jit
def step(p, opt_state, t):
    loss, grads = jax.value_and_grad(lambda p: jnp.mean((net(p, x) - y) ** 2))(p)
    updates, opt_state = adam.update(grads, opt_state)
    return optax.apply_updates(p, jax.tree.map(lambda u: -lr(t) * u, updates)), opt_state, loss


cut = jax.jit(lambda p, s: lowrank.truncate(p, s, rule="cumulative", beta=0.98, optimizer=adam))
opt_state = adam.init(params)
for t in range(STEPS):
    params, opt_state, loss = step(params, opt_state, t)
    if (t + 1) % CUT_EVERY == 0:
        params, opt_state, records = cut(params, opt_state)
        r = records["['mid']"]
        print(f"step {t + 1}: loss {loss:.4f}, rank {int(r.old_rank)} -> {int(r.applied)}")
