"""A trained policy taken out of a run: `policy` (`adarl export`, the NumPy-only .npz file that
`adarl.policy.load` runs) and `video` (`adarl play`, its rollouts rendered offscreen)."""
