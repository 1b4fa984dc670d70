"""The proposal network's input, layers and decoding, shared by its trainer (proposals.py), the ONNX file the core
runs through cv::dnn (csrc/detect/proposal_net.cpp) and the tests.

Input (the same arithmetic as the core's `ProposalNet`): the gray image resized to `input_width` x floor(height *
input_width / width + 0.5) by the pixel-area mean (cv2.resize INTER_AREA), then z = (g - INPUT_MEAN) / INPUT_SCALE.

Network (ONNX opset 11, every node cv::dnn of OpenCV 4.6 reads), fully convolutional, output stride 4:
    a0 = relu(conv3x3/2(z, c))                                   (c, H/2, W/2)
    a1 = relu(conv1x1(relu(dwconv3x3/2(a0)), C))                 (C, H/4, W/4)
    a_{k+1} = a_k + relu(conv1x1(relu(dwconv3x3(a_k)), C))      k = 1 .. BLOCKS
    heat = sigmoid(conv1x1(a, 1))        the objectness of each cell: a vehicle's centre is a peak
    box  = conv1x1(a, 4)                 log(distance / STRIDE) from the cell's centre to the box's left, top,
                                         right and bottom edges
("/2": stride 2; convolutions pad to keep the size, ceil(n / 2) after a stride; "dw": depthwise.) Each output cell
sees 71 px of the input (284 px of a 1280x720 image), at ~43 M multiply-adds for 320x180. Dilated depthwise layers
would see farther for the same arithmetic, but cv::dnn runs them ~6x slower (docs/decisions.md).

Decoding (`decode`, and the core's the same way): a cell is a peak when its heat is the largest of its 3x3
neighbourhood and at least `min_heat`; its box in the input is
    (x_c - e^{b0} S, y_c - e^{b1} S, x_c + e^{b2} S, y_c + e^{b3} S),   x_c = S j + 0.5, y_c = S i + 0.5,  S = STRIDE
and the image's box is that times the image's size over the input's.
"""
from __future__ import annotations

import cv2
import numpy as np

STRIDE = 4               # input px per output cell
INPUT_WIDTH = 320        # px: the shipped model's input width (the 1280x720 images at a quarter)
INPUT_MEAN, INPUT_SCALE = 127.5, 64.0
STEM, WIDTH = 16, 32     # channels of the first convolution and of every layer after it
BLOCKS = 8               # residual depthwise-separable blocks at stride 4
OPSET = 11


def input_size(width: int, height: int, input_width: int = INPUT_WIDTH) -> tuple[int, int]:
    """The network's input (width, height) for an image of `width` x `height`: the aspect kept."""
    return input_width, max(STRIDE, int(np.floor(height * input_width / width + 0.5)))


def output_size(w_in: int, h_in: int) -> tuple[int, int]:
    """(width, height) of the output maps: ceil twice by 2."""
    half = lambda n: (n + 1) // 2  # noqa: E731
    return half(half(w_in)), half(half(h_in))


def prepare(gray: np.ndarray, input_width: int = INPUT_WIDTH) -> np.ndarray:
    """(H_in, W_in) uint8: the image resized as the core resizes it."""
    w, h = input_size(gray.shape[1], gray.shape[0], input_width)
    return cv2.resize(gray, (w, h), interpolation=cv2.INTER_AREA)


def standardise(small: np.ndarray) -> np.ndarray:
    """(n, 1, H, W) float32 network input of uint8 images (n, H, W) or one (H, W)."""
    s = np.asarray(small, np.float32)
    s = s[None] if s.ndim == 2 else s
    return ((s - INPUT_MEAN) / INPUT_SCALE)[:, None]


def init_params(seed: int, stem: int = STEM, width: int = WIDTH, blocks: int = BLOCKS) -> dict:
    """He-normal weights, zero biases; the heat head's bias starts at a prior of 0.01 (CenterNet)."""
    rng = np.random.default_rng(seed)
    he = lambda shape, fan: rng.normal(0, np.sqrt(2 / fan), shape).astype(np.float32)  # noqa: E731
    p = {"stem_w": he((stem, 1, 3, 3), 9), "stem_b": np.zeros(stem, np.float32),
         "down_dw": he((stem, 1, 3, 3), 9), "down_dwb": np.zeros(stem, np.float32),
         "down_pw": he((width, stem, 1, 1), stem), "down_pwb": np.zeros(width, np.float32)}
    for k in range(blocks):
        p[f"b{k}_dw"] = he((width, 1, 3, 3), 9)
        p[f"b{k}_dwb"] = np.zeros(width, np.float32)
        p[f"b{k}_pw"] = (he((width, width, 1, 1), width) * 0.5).astype(np.float32)  # residual: start small
        p[f"b{k}_pwb"] = np.zeros(width, np.float32)
    p["heat_w"] = rng.normal(0, 0.01, (1, width, 1, 1)).astype(np.float32)
    p["heat_b"] = np.float32([-np.log(99.0)])
    p["box_w"] = rng.normal(0, 0.01, (4, width, 1, 1)).astype(np.float32)
    p["box_b"] = np.full(4, np.log(2.0), np.float32)   # 2 cells each way: a car of ~32 px at the start
    return p


def blocks_of(params: dict) -> int:
    """The number of residual blocks a parameter set holds."""
    return sum(k.endswith("_dw") and k.startswith("b") for k in params)


def forward_jax(p: dict, z):
    """(heat logits (n, 1, h, w), box (n, 4, h, w)) of the standardised input z (n, 1, H, W), in JAX.

    The depthwise 3x3 convolutions are written as nine shifted products and the 1x1 as contractions: XLA's CPU
    grouped convolution (feature_group_count) made a gradient step ~4x slower (docs/decisions.md)."""
    # JAX is optional (pip install '.[train]'): imported only where a network is fitted, written or read
    import jax.numpy as jnp
    from jax import lax

    def conv(x, w, b, stride=1):
        pad = w.shape[-1] // 2
        y = lax.conv_general_dilated(x, w, (stride, stride), ((pad, pad), (pad, pad)),
                                     dimension_numbers=("NCHW", "OIHW", "NCHW"))
        return y + b[None, :, None, None]

    def pointwise(x, w, b):
        return jnp.einsum("nchw,oc->nohw", x, w[:, :, 0, 0]) + b[None, :, None, None]

    def depthwise(x, w, b, stride=1):
        h, wd = x.shape[2], x.shape[3]
        ho, wo = (h + stride - 1) // stride, (wd + stride - 1) // stride
        xp = jnp.pad(x, ((0, 0), (0, 0), (1, 1), (1, 1)))
        acc = b[None, :, None, None]
        for i in range(3):
            for j in range(3):
                acc = acc + xp[:, :, i:i + stride * (ho - 1) + 1:stride, j:j + stride * (wo - 1) + 1:stride] \
                    * w[None, :, 0, i, j, None, None]
        return acc

    relu = lambda x: jnp.maximum(x, 0)  # noqa: E731
    a = relu(conv(z, p["stem_w"], p["stem_b"], 2))
    a = relu(pointwise(relu(depthwise(a, p["down_dw"], p["down_dwb"], 2)), p["down_pw"], p["down_pwb"]))
    for k in range(blocks_of(p)):
        a = a + relu(pointwise(relu(depthwise(a, p[f"b{k}_dw"], p[f"b{k}_dwb"])), p[f"b{k}_pw"], p[f"b{k}_pwb"]))
    return pointwise(a, p["heat_w"], p["heat_b"]), pointwise(a, p["box_w"], p["box_b"])


def decode(heat: np.ndarray, box: np.ndarray, scale_x: float, scale_y: float, min_heat: float,
           top_k: int = 100) -> np.ndarray:
    """(n, 6) left, top, right, bottom (image px), heat, and the peak's index (row * w + column): the peaks of one
    image's heat map (h, w) at least `min_heat`, strongest first, at most top_k; box (4, h, w) the box output;
    scale_x, scale_y: image px per input px."""
    h, w = heat.shape
    peak = (heat >= cv2.dilate(heat, np.ones((3, 3), np.uint8))) & (heat >= min_heat)
    i, j = np.nonzero(peak)
    order = np.argsort(-heat[i, j], kind="stable")[:top_k]
    i, j = i[order], j[order]
    d = np.exp(box[:, i, j]) * STRIDE
    xc, yc = STRIDE * j + 0.5, STRIDE * i + 0.5
    return np.c_[(xc - d[0]) * scale_x, (yc - d[1]) * scale_y, (xc + d[2]) * scale_x, (yc + d[3]) * scale_y,
                 heat[i, j], i * w + j].astype(np.float64)


# ---- ONNX ----

def save_onnx(params: dict, path: str, doc: str = "") -> None:
    """Write the network as ONNX (opset 11): input `image` (1, 1, H, W) (any size: fully convolutional), outputs
    `heat` (1, 1, h, w) after the sigmoid and `box` (1, 4, h, w)."""
    # onnx is optional (pip install '.[train]'): imported only where a network is fitted, written or read
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    p = {k: np.asarray(v, np.float32) for k, v in params.items()}
    init = [numpy_helper.from_array(v, k) for k, v in p.items()]
    nodes = []

    def conv(x, w, b, out, stride=1, group=1):
        k = p[w].shape[-1]
        nodes.append(helper.make_node("Conv", [x, w, b], [out], kernel_shape=[k, k], pads=[k // 2] * 4,
                                      strides=[stride, stride], group=group))
        return out

    def relu(x):
        nodes.append(helper.make_node("Relu", [x], [x + "_r"]))
        return x + "_r"

    stem, width = p["stem_w"].shape[0], p["down_pw"].shape[0]
    a = relu(conv("image", "stem_w", "stem_b", "stem", 2))
    a = relu(conv(relu(conv(a, "down_dw", "down_dwb", "down_d", 2, group=stem)), "down_pw", "down_pwb", "down"))
    for k in range(blocks_of(p)):
        y = relu(conv(relu(conv(a, f"b{k}_dw", f"b{k}_dwb", f"b{k}_d", 1, group=width)), f"b{k}_pw", f"b{k}_pwb",
                      f"b{k}_p"))
        nodes.append(helper.make_node("Add", [a, y], [f"b{k}"]))
        a = f"b{k}"
    conv(a, "heat_w", "heat_b", "heat_logit")
    nodes.append(helper.make_node("Sigmoid", ["heat_logit"], ["heat"]))
    conv(a, "box_w", "box_b", "box")
    graph = helper.make_graph(
        nodes, "headway_vehicle_proposals",
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 1, "H", "W"])],
        [helper.make_tensor_value_info("heat", TensorProto.FLOAT, [1, 1, "h", "w"]),
         helper.make_tensor_value_info("box", TensorProto.FLOAT, [1, 4, "h", "w"])], init)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="headway",
                              doc_string=doc)
    model.ir_version = 7
    onnx.checker.check_model(model)
    onnx.save(model, path)


def run_onnx(path: str, small: np.ndarray):
    """(heat (h, w), box (4, h, w)) of one resized image (H_in, W_in) uint8 by cv2.dnn, as the core runs it."""
    net = cv2.dnn.readNetFromONNX(path)
    net.setInput(standardise(small), "image")
    heat, box = net.forward(["heat", "box"])
    return heat[0, 0], box[0]
