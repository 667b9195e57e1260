"""The names the networks accept, without JAX: the configs validate against them before any
network is built (`adarl.nets.mlp`, `adarl.nets.rank` implement them)."""

ACTIVATIONS = ("relu", "tanh")
INITS = ("torch", "orthogonal")
RANK_RULES = ("cumulative", "ratio", "energy", "energy-squared")
LR_SCHEDULES = ("envelope", "restart")
