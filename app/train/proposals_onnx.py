"""The proposal network's input, layers and decoding, shared by its trainer (proposals.py), the ONNX file the core
runs through cv::dnn (csrc/detect/proposals/proposal_net.cpp) and the tests.

Input (the same arithmetic as the core's `ProposalNet`): the gray image resized to `input_width` x floor(height *
input_width / width + 0.5) by the pixel-area mean (cv2.resize INTER_AREA), then z = (g - INPUT_MEAN) / INPUT_SCALE.

Network (ONNX opset 11, every node cv::dnn of OpenCV 4.6 reads), fully convolutional, its last level at stride 8 (4
for a network without the third level):
    a0 = relu(conv3x3/2(z, c))                                   (c, H/2, W/2)
    a1 = relu(conv1x1(relu(dwconv3x3/2(a0)), C))                 (C, H/4, W/4)
    a_{k+1} = a_k + relu(conv1x1(relu(dwconv3x3(a_k)), C))      k = 1 .. BLOCKS
    b1 = relu(conv1x1(relu(dwconv3x3/2(a)), C8))                 (C8, H/8, W/8)
    b_{k+1} = b_k + relu(conv1x1(relu(dwconv3x3(b_k)), C8))     k = 1 .. BLOCKS8
    heat = sigmoid(conv1x1(b, s^2))      the objectness of each cell: a vehicle's centre is a peak
    box  = conv1x1(b, 4 s^2)             log(distance / stride) from the cell's centre to the box's left, top,
                                         right and bottom edges
With s = SUBCELLS = 2 sub-cells (the shipped model) each cell of the last level carries its s x s sub-cells (heat channel s di + dj, box channel
s^2 k + s di + dj for edge k: the sub-cell at row s i + di, column s j + dj), so the grid's stride is the last
level's over s: two vehicles one cell apart give two peaks. `to_grid` lays the maps out on that grid, as the core does.
("/2": stride 2; convolutions pad to keep the size, ceil(n / 2) after a stride; "dw": depthwise.) Each output cell
sees 127 px of the input (508 px of a 1280x720 image), at ~42 M multiply-adds for 320x180: the third level gives the
large near vehicles' edges to the cell at their centre (eight blocks at stride 4 alone see 71 px for as much). Dilated depthwise layers would see farther for the same
arithmetic, but cv::dnn runs them ~6x slower (docs/decisions.md).

Decoding (`decode`, and the core's the same way): a cell is a peak when its heat is the largest of its 3x3
neighbourhood and at least `min_heat`; its box in the input is
    (x_c - e^{b0} S, y_c - e^{b1} S, x_c + e^{b2} S, y_c + e^{b3} S),   x_c = S j + 0.5, y_c = S i + 0.5,  S = the
grid's stride
and the image's box is that times the image's size over the input's.
"""
from __future__ import annotations

import cv2
import numpy as np

INPUT_WIDTH = 320        # px: the shipped model's input width (the 1280x720 images at a quarter)
INPUT_MEAN, INPUT_SCALE = 127.5, 64.0
STEM, WIDTH = 16, 32     # channels of the first convolution and of the stride-4 layers
BLOCKS = 2               # residual depthwise-separable blocks at stride 4
WIDTH8, BLOCKS8 = 64, 6  # channels and blocks at stride 8 (BLOCKS8 = 0: no third level, output stride 4)
SUBCELLS = 2             # sub-cells a side of each last-level cell (module docstring): 1 or 2
OPSET = 11


def input_size(width: int, height: int, input_width: int = INPUT_WIDTH) -> tuple[int, int]:
    """The network's input (width, height) for an image of `width` x `height`: the aspect kept."""
    return input_width, max(8, int(np.floor(height * input_width / width + 0.5)))


def output_size(w_in: int, h_in: int, stride: int = 8, subcells: int = 1) -> tuple[int, int]:
    """(width, height) of the grid (to_grid) of a network whose grid has this stride: the last level's maps (ceil
    by 2, log2(stride * subcells) times) times the sub-cells."""
    for _ in range(int(np.log2(stride * subcells))):
        w_in, h_in = (w_in + 1) // 2, (h_in + 1) // 2
    return w_in * subcells, h_in * subcells


def prepare(gray: np.ndarray, input_width: int = INPUT_WIDTH) -> np.ndarray:
    """(H_in, W_in) uint8: the image resized as the core resizes it."""
    w, h = input_size(gray.shape[1], gray.shape[0], input_width)
    return cv2.resize(gray, (w, h), interpolation=cv2.INTER_AREA)


def standardise(small: np.ndarray) -> np.ndarray:
    """(n, 1, H, W) float32 network input of uint8 images (n, H, W) or one (H, W)."""
    s = np.asarray(small, np.float32)
    s = s[None] if s.ndim == 2 else s
    return ((s - INPUT_MEAN) / INPUT_SCALE)[:, None]


def init_params(seed: int, stem: int = STEM, width: int = WIDTH, blocks: int = BLOCKS, width8: int = WIDTH8,
                blocks8: int = BLOCKS8, subcells: int = SUBCELLS) -> dict:
    """He-normal weights, zero biases; the heat head's bias starts at a prior of 0.01 (CenterNet). blocks8 = 0: no
    third level (output stride 4)."""
    rng = np.random.default_rng(seed)
    he = lambda shape, fan: rng.normal(0, np.sqrt(2 / fan), shape).astype(np.float32)  # noqa: E731

    def separable(name, c_in, c_out, residual):
        p[f"{name}_dw"], p[f"{name}_dwb"] = he((c_in, 1, 3, 3), 9), np.zeros(c_in, np.float32)
        p[f"{name}_pw"] = (he((c_out, c_in, 1, 1), c_in) * (0.5 if residual else 1.0)).astype(np.float32)
        p[f"{name}_pwb"] = np.zeros(c_out, np.float32)   # residual: start small

    p = {"stem_w": he((stem, 1, 3, 3), 9), "stem_b": np.zeros(stem, np.float32)}
    separable("down", stem, width, False)
    for k in range(blocks):
        separable(f"b{k}", width, width, True)
    head = width
    if blocks8 > 0:
        separable("down8", width, width8, False)
        for k in range(blocks8):
            separable(f"c{k}", width8, width8, True)
        head = width8
    if subcells not in (1, 2):
        raise ValueError(f"subcells={subcells}: 1 or 2")
    n = subcells * subcells
    p["heat_w"] = rng.normal(0, 0.01, (n, head, 1, 1)).astype(np.float32)
    p["heat_b"] = np.full(n, -np.log(99.0), np.float32)
    p["box_w"] = rng.normal(0, 0.01, (4 * n, head, 1, 1)).astype(np.float32)
    p["box_b"] = np.full(4 * n, np.log(2.0), np.float32)   # 2 cells each way at the start
    return p


def blocks_of(params: dict, level: str = "b") -> int:
    """The number of residual blocks a parameter set holds at stride 4 (level "b") or 8 ("c")."""
    return sum(k.startswith(level) and k.endswith("_dw") and k[1:-3].isdigit() for k in params)


def subcells_of(params: dict) -> int:
    """Sub-cells a side of each last-level cell (1 or 2)."""
    return int(round(np.sqrt(params["heat_w"].shape[0])))


def stride_of(params: dict) -> int:
    """The grid's stride in input px: the last level's (8 with the third level, else 4) over the sub-cells."""
    return (8 if "down8_dw" in params else 4) // subcells_of(params)


def to_grid(heat, box):
    """(heat (..., 1, s h, s w), box (..., 4, s h, s w)): the maps as the network gives them, heat (..., s^2, h, w)
    and box (..., 4 s^2, h, w), laid out on the grid (module docstring); numpy or JAX arrays, any leading axes."""
    *lead, n, h, w = heat.shape
    s = int(round(np.sqrt(n)))
    k = len(lead)
    order = tuple(range(k)) + (k, k + 3, k + 1, k + 4, k + 2)   # (..., c, di, dj, i, j) -> (..., c, i, di, j, dj)
    grid = heat.reshape(*lead, 1, s, s, h, w).transpose(order).reshape(*lead, 1, s * h, s * w)
    b = box.reshape(*lead, 4, s, s, h, w).transpose(order).reshape(*lead, 4, s * h, s * w)
    return grid, b


def layers(params: dict) -> list[tuple[str, int, bool]]:
    """(name, stride, residual) of each depthwise-separable layer after the stem, in order."""
    out = [("down", 2, False)] + [(f"b{k}", 1, True) for k in range(blocks_of(params, "b"))]
    if "down8_dw" in params:
        out += [("down8", 2, False)] + [(f"c{k}", 1, True) for k in range(blocks_of(params, "c"))]
    return out


def forward_jax(p: dict, z):
    """(heat logits (n, 1, s h, s w), box (n, 4, s h, s w)) on the grid (to_grid) of the standardised input z
    (n, 1, H, W), in JAX.

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
    for name, stride, residual in layers(p):
        y = relu(pointwise(relu(depthwise(a, p[f"{name}_dw"], p[f"{name}_dwb"], stride)), p[f"{name}_pw"],
                           p[f"{name}_pwb"]))
        a = a + y if residual else y
    return to_grid(pointwise(a, p["heat_w"], p["heat_b"]), pointwise(a, p["box_w"], p["box_b"]))


def decode(heat: np.ndarray, box: np.ndarray, scale_x: float, scale_y: float, min_heat: float,
           top_k: int = 100, stride: int = 8) -> np.ndarray:
    """(n, 6) left, top, right, bottom (image px), heat, and the peak's index (row * w + column): the peaks of one
    image's heat map (h, w) at least `min_heat`, strongest first, at most top_k; box (4, h, w) the box output;
    scale_x, scale_y: image px per input px; stride: input px per output cell."""
    h, w = heat.shape
    peak = (heat >= cv2.dilate(heat, np.ones((3, 3), np.uint8))) & (heat >= min_heat)
    i, j = np.nonzero(peak)
    order = np.argsort(-heat[i, j], kind="stable")[:top_k]
    i, j = i[order], j[order]
    d = np.exp(box[:, i, j]) * stride
    xc, yc = stride * j + 0.5, stride * i + 0.5
    return np.c_[(xc - d[0]) * scale_x, (yc - d[1]) * scale_y, (xc + d[2]) * scale_x, (yc + d[3]) * scale_y,
                 heat[i, j], i * w + j].astype(np.float64)


# ---- ONNX ----

def save_onnx(params: dict, path: str, doc: str = "") -> None:
    """Write the network as ONNX (opset 11): input `image` (1, 1, H, W) (any size: fully convolutional), outputs
    `heat` (1, s^2, h, w) after the sigmoid and `box` (1, 4 s^2, h, w) (s sub-cells a side, module docstring)."""
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

    a = relu(conv("image", "stem_w", "stem_b", "stem", 2))
    for name, stride, residual in layers(p):
        y = relu(conv(relu(conv(a, f"{name}_dw", f"{name}_dwb", f"{name}_d", stride, group=p[f"{name}_dw"].shape[0])),
                      f"{name}_pw", f"{name}_pwb", f"{name}_p"))
        if residual:
            nodes.append(helper.make_node("Add", [a, y], [name]))
            y = name
        a = y
    conv(a, "heat_w", "heat_b", "heat_logit")
    nodes.append(helper.make_node("Sigmoid", ["heat_logit"], ["heat"]))
    conv(a, "box_w", "box_b", "box")
    graph = helper.make_graph(
        nodes, "headway_vehicle_proposals",
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 1, "H", "W"])],
        [helper.make_tensor_value_info("heat", TensorProto.FLOAT, [1, p["heat_w"].shape[0], "h", "w"]),
         helper.make_tensor_value_info("box", TensorProto.FLOAT, [1, p["box_w"].shape[0], "h", "w"])], init)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="headway",
                              doc_string=doc)
    model.ir_version = 7
    onnx.checker.check_model(model)
    onnx.save(model, path)


def run_onnx(path: str, small: np.ndarray):
    """(heat (h, w), box (4, h, w)) on the grid (to_grid) of one resized image (H_in, W_in) uint8 by cv2.dnn, as the
    core runs it."""
    net = cv2.dnn.readNetFromONNX(path)
    net.setInput(standardise(small), "image")
    heat, box = to_grid(*(m[0] for m in net.forward(["heat", "box"])))
    return heat[0], box
