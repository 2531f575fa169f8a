"""A minimal ONNX writer: a graph of nodes and float32 weights as the bytes of an ONNX model.

It writes the few Protocol Buffers messages a feed-forward graph needs (the model, its graph,
nodes with integer attributes, float tensors, typed inputs and outputs); OpenCV's `dnn` module
runs them from bytes. Field numbers are those of onnx/onnx.proto (IR version 7, opset 13).
Repeated numbers are written unpacked, one field each.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

IR_VERSION = 7
OPSET = 13
FLOAT = 1  # TensorProto.DataType
INT64 = 7
ATTRIBUTE_FLOAT, ATTRIBUTE_INT, ATTRIBUTE_INTS = 1, 2, 7  # AttributeProto.AttributeType


def varint(value: int) -> bytes:
    """A protobuf varint; a negative int64 as its 64-bit two's complement (ten bytes)."""
    value &= (1 << 64) - 1
    out = bytearray()
    while True:
        low = value & 0x7F
        value >>= 7
        if value:
            out.append(low | 0x80)
        else:
            out.append(low)
            return bytes(out)


def int_field(number: int, value: int) -> bytes:
    return varint(number << 3) + varint(value)


def bytes_field(number: int, value: bytes | str) -> bytes:
    data = value.encode() if isinstance(value, str) else value
    return varint(number << 3 | 2) + varint(len(data)) + data


def float_field(number: int, value: float) -> bytes:
    return varint(number << 3 | 5) + struct.pack("<f", value)


def tensor(name: str, array: np.ndarray) -> bytes:
    """A TensorProto: dims, data type, name and little-endian raw data (float32 or int64)."""
    array = np.asarray(array)
    kind = INT64 if np.issubdtype(array.dtype, np.integer) else FLOAT
    data = array.astype("<i8" if kind == INT64 else "<f4").tobytes()
    dims = b"".join(int_field(1, n) for n in array.shape)
    return dims + int_field(2, kind) + bytes_field(8, name) + bytes_field(9, data)


def value_info(name: str, shape: Sequence[int]) -> bytes:
    """A ValueInfoProto: a float tensor's name and shape."""
    dims = b"".join(bytes_field(1, int_field(1, n)) for n in shape)
    tensor_type = int_field(1, FLOAT) + bytes_field(2, dims)
    return bytes_field(1, name) + bytes_field(2, bytes_field(1, tensor_type))


def attribute(name: str, value: int | float | Sequence[int]) -> bytes:
    if isinstance(value, float):
        return bytes_field(1, name) + float_field(2, value) + int_field(20, ATTRIBUTE_FLOAT)
    if isinstance(value, int):
        return bytes_field(1, name) + int_field(3, value) + int_field(20, ATTRIBUTE_INT)
    ints = b"".join(int_field(8, v) for v in value)
    return bytes_field(1, name) + ints + int_field(20, ATTRIBUTE_INTS)


@dataclass
class Graph:
    """Nodes in order and named weights, grown by `add` and `weight`, written by `model`."""

    nodes: list[bytes] = field(default_factory=list)
    weights: list[bytes] = field(default_factory=list)
    count: int = 0

    def weight(self, name: str, array: np.ndarray) -> str:
        self.weights.append(tensor(name, array))
        return name

    def add(
        self,
        op: str,
        inputs: Sequence[str],
        output: str | None = None,
        **attributes: int | float | Sequence[int],
    ) -> str:
        """Append a node `op` reading `inputs`; returns its output's name."""
        self.count += 1
        output = output or f"{op.lower()}{self.count}"
        node = b"".join(bytes_field(1, name) for name in inputs)
        node += bytes_field(2, output) + bytes_field(3, f"n{self.count}") + bytes_field(4, op)
        node += b"".join(bytes_field(5, attribute(k, v)) for k, v in attributes.items())
        self.nodes.append(node)
        return output

    def model(
        self,
        inputs: Mapping[str, Sequence[int]],
        outputs: Mapping[str, Sequence[int]],
        name: str = "graph",
    ) -> bytes:
        """The ModelProto's bytes."""
        graph = b"".join(bytes_field(1, node) for node in self.nodes) + bytes_field(2, name)
        graph += b"".join(bytes_field(5, weight) for weight in self.weights)
        graph += b"".join(bytes_field(11, value_info(k, s)) for k, s in inputs.items())
        graph += b"".join(bytes_field(12, value_info(k, s)) for k, s in outputs.items())
        opset = bytes_field(1, "") + int_field(2, OPSET)
        return (
            int_field(1, IR_VERSION)
            + bytes_field(2, "servant")
            + bytes_field(7, graph)
            + bytes_field(8, opset)
        )
