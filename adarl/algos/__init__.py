"""The algorithms: their configs and presets (`config`, `sac_config`, `rnac_config`, JAX-free),
their maths (`sac`: the SAC family, SAC, AdaRL, fixed-rank, Parseval, sparse; `rnac`), each
networks, losses and a jitted update, and `registry`, which names them (config class, defaults,
presets, roles). The training loops live in `adarl/train`."""
