"""The worker wire format: every array comes back with its dtype, shape and bytes."""

import io

import numpy as np
import pytest

from openral_mjx.host.codec import decode, encode, read_frame


def test_round_trip_nested_arrays_and_scalars():
    rng = np.random.default_rng(0)
    msg = {
        "op": "call",
        "kwargs": {
            "f32": rng.standard_normal((3, 4)).astype(np.float32),
            "u8": rng.integers(0, 255, (2, 5, 5, 3), dtype=np.uint8),
            "f64_strided": rng.standard_normal((6, 6))[::2, 1::2],
            "bool": np.array([True, False, True]),
            "i64_scalar": np.int64(-7),
            "empty": np.zeros((0, 3), np.int32),
            "list": [1, 2.5, None, "x", np.arange(3, dtype=np.uint16)],
        },
    }
    back = decode(encode(msg))
    assert back["op"] == "call"
    for key, value in msg["kwargs"].items():
        if key == "list":
            assert back["kwargs"]["list"][:4] == [1, 2.5, None, "x"]
            np.testing.assert_array_equal(back["kwargs"]["list"][4], value[4])
            assert back["kwargs"]["list"][4].dtype == np.uint16
            continue
        got = back["kwargs"][key]
        assert got.dtype == np.asarray(value).dtype and got.shape == np.shape(value), key
        np.testing.assert_array_equal(got, value)
        assert got.flags.writeable


def test_frames_follow_each_other_on_a_stream():
    stream = io.BytesIO(encode({"a": np.ones(2)}) + encode({"b": 2}))
    assert read_frame(stream)["a"].tolist() == [1.0, 1.0]
    assert read_frame(stream) == {"b": 2}
    with pytest.raises(EOFError):
        read_frame(stream)


def test_object_arrays_and_unknown_types_are_refused():
    with pytest.raises(TypeError, match="object array"):
        encode({"x": np.array([object()])})
    with pytest.raises(TypeError, match="set"):
        encode({"x": {1, 2}})
