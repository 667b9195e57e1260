"""Test helper shared by the lane-independence tests of tests/train: a one-seed run's checkpoint
arrays against its seed's slice of a run of several seeds."""

import numpy as np


def assert_seed_slice_equal(alone: dict, together: dict, index: int) -> None:
    """Every array of `alone` (a checkpoint's arrays, one seed) equals seed `index`'s part of
    `together` (the same checkpoint of a run of several seeds): the environment's state under
    `env/<index>/`; replay rows up to the seed's own count, zeros past it (a run saves as many rows
    as its fullest seed's buffer needs); every other array, stacked over seeds, at `index`."""
    for key, value in alone.items():
        if key.startswith("env/0/"):
            np.testing.assert_array_equal(together[f"env/{index}/" + key[6:]], value, err_msg=key)
        elif key.startswith("buffer/") and value.ndim > 1:
            mine = together[key][index]
            np.testing.assert_array_equal(mine[: len(value[0])], value[0], err_msg=key)
            assert not mine[len(value[0]) :].any(), key
        else:
            np.testing.assert_array_equal(together[key][index], value[0], err_msg=key)
