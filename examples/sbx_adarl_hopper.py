"""AdaRL in Stable-Baselines-JAX: SBX's SAC on adarl/Hopper-v0, the 2nd hidden layer of actor and
critics a bottleneck W1·W2 cut every d_t steps (Eq. 5, reset, warm-up). Args: [steps d_t]"""

import sys

import flax.linen as nn
import jax.numpy as jnp
from sbx import SAC
from sbx.common.distributions import TanhTransformedDistribution, tfd
from sbx.common.policies import ContinuousCritic, SquashedGaussianActor, VectorCritic
from stable_baselines3.common.callbacks import BaseCallback

from adarl import lowrank
from adarl.lowrank.linen import FactorisedDense

STEPS, D_T = map(int, sys.argv[1:3]) if len(sys.argv) > 2 else (100_000, 10_000)


def trunk(x, sizes, act):  # the second hidden layer is the bottleneck (masked, at full rank)
    return act(FactorisedDense(sizes[1], rank=sizes[1])(act(nn.Dense(sizes[0])(x))))


class Actor(SquashedGaussianActor):
    @nn.compact
    def __call__(self, x):
        h, n = trunk(x, self.net_arch, self.activation_fn), self.action_dim
        std = jnp.exp(jnp.clip(nn.Dense(n)(h), self.log_std_min, self.log_std_max))
        return TanhTransformedDistribution(tfd.MultivariateNormalDiag(nn.Dense(n)(h), std))


class Critic(ContinuousCritic):
    @nn.compact
    def __call__(self, x, a):
        return nn.Dense(1)(trunk(jnp.concatenate([x, a], -1), self.net_arch, self.activation_fn))


class Critics(VectorCritic):
    @nn.compact
    def __call__(self, obs, a):
        return nn.vmap(Critic, variable_axes={"params": 0}, split_rngs={"params": True},
                       in_axes=None, axis_size=self.n_critics)(self.net_arch)(obs, a)  # fmt: skip


class Truncate(BaseCallback):
    def _on_step(self):
        for name in ("actor_state", "qf_state") if self.num_timesteps % D_T == 0 else ():
            s = getattr(self.model.policy, name)
            new, opt, records = lowrank.truncate(s.params, s.opt_state, beta=0.98, optimizer=s.tx)
            copy = {"target_params": new} if name == "qf_state" else {}  # targets copy the cut
            setattr(self.model.policy, name, s.replace(params=new, opt_state=opt, **copy))
            for path, r in records.items():
                self.logger.record(f"rank/{name}{path}", r.applied.tolist())
                print(f"step {self.num_timesteps} {name}{path}: rank {r.applied.tolist()}")
        return True


lr = lowrank.envelope_schedule(3e-4, total_steps=STEPS, warmup_steps=D_T // 10, cut_every=D_T)
SAC("MlpPolicy", "adarl:adarl/Hopper-v0", lambda p: float(lr(round((1 - p) * STEPS))), seed=0,
    policy_kwargs=dict(actor_class=Actor, vector_critic_class=Critics)).learn(STEPS, Truncate())  # fmt: skip
