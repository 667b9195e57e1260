"""The codecs of a checkpoint: environment states as meta.json trees with their arrays beside."""

import json

import numpy as np

from adarl.runs.codec import decode_env_state, encode_env_state


def test_env_state_codec_round_trip():
    state = {
        "a": np.arange(3.0),
        "t": (1, np.int64(2), [np.zeros((2, 2), np.float32)]),
        "d": {"x": None, "y": "text", "z": np.float64(0.5)},
    }
    arrays: dict = {}
    encoded = encode_env_state(state, arrays, "env/0")
    json.dumps(encoded)  # meta.json-able
    back = decode_env_state(json.loads(json.dumps(encoded)), arrays)
    assert isinstance(back["t"], tuple) and back["t"][1] == 2 and back["d"] == state["d"]
    np.testing.assert_array_equal(back["a"], state["a"])
    assert back["t"][2][0].dtype == np.float32 and sorted(arrays) == ["env/0/a", "env/0/t/2/0"]
    # the SAC loop's encoding of run format 1: arrays inline in meta.json
    old = {"a": {"__ndarray__": [1.0, 2.0], "dtype": "float32"}, "b": [1, 2]}
    legacy = decode_env_state(old, {})
    assert legacy["a"].dtype == np.float32 and legacy["b"] == [1, 2]
