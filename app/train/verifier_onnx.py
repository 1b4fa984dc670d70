"""The convolutional verifier's input and network, shared by its trainer (verifier_cnn.py), the ONNX file the
core runs through cv::dnn (csrc/detect/vehicle_verifier_cnn.cpp) and the tests.

Input (the same arithmetic as the core's `CnnVerifier`):
- crop: the box widened by `MARGIN` of its size on each side (context: the road under the vehicle, its
  sides), rounded to whole pixels, reduced to `CROP_W` x `CROP_H` gray by the pixel-area mean: inside the image
  and at least the crop's size, each cell's mean from the image's integral (`area_cells`); otherwise the outside
  filled by replicating the border (cv::copyMakeBorder, BORDER_REPLICATE) and cv::resize (INTER_AREA), which
  also averages pixel areas (and interpolates where it enlarges); then standardised by its own mean and
  standard deviation, z = (c - mean) / (std + 1) (lighting-free);
- extra: log(1 + n) of the n raw cascade windows grouped, and the vehicle height the box implies on a flat
  road (m, verifier.geometry_features); standardised inside the network (folded into the first dense layer).

Network (ONNX opset 11, every node cv::dnn of OpenCV 4.6 reads):
    a1 = maxpool2(relu(conv3x3(z, c1)))       (c1, H/2, W/2)
    a2 = maxpool2(relu(conv3x3(a1, c2)))      (c2, H/4, W/4)
    a3 = maxpool2(relu(conv3x3(a2, c3)))      (c3, H/8, W/8)
    h  = relu(W_h [flatten(a3), (extra - mean_e) * scale_e] + b_h)
    p  = sigmoid(w_o . h + b_o)
    d  = W_d h + b_d                          (4: the box output, when the network has one)
The box output refines the box (l, t, r, b) the crop was cut from (`refine`):
    l' = l + d_0 w,   t' = t + d_1 h,   r' = r + d_2 w,   b' = b + d_3 h,   w = r - l, h = b - t.
Convolutions pad by one pixel (same size), pools are 2x2 with stride 2; flatten is in (channel, row, column)
order as ONNX's Flatten of NCHW.
"""
from __future__ import annotations

import cv2
import numpy as np

CROP_W, CROP_H = 48, 32   # px: the cascade's aspect 1.5; a 40 px box (the scored band's smallest) at ~1:1
MARGIN = 0.1              # of the box's width (height) added left and right (top and bottom); a network with
                          # the box output carries its own (`crop_margin`, output `margin`), read by the core
OPSET = 11                # read by OpenCV 4.6's ONNX importer


def area_cells(ii: np.ndarray, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
    """(CROP_H, CROP_W) uint8: the rounded mean of each cell of a CROP_W x CROP_H grid over the source rectangle
    [x0, x1) x [y0, y1) (whole pixels, inside the image, at least the crop's size), from the image's integral `ii`
    ((rows + 1) x (cols + 1), cv2.integral). The integral of a piecewise-constant image is bilinear between whole
    pixels, so every cell corner's integral is an exact bilinear read: the pixel-area mean cv2.resize(INTER_AREA)
    computes (its float weights differ by one grey level on ~0.1 % of the pixels), at a cost per cell rather than
    per source pixel. The core's `area_cells` (vehicle_verifier_cnn.cpp) does the same in the same order."""
    ii = np.asarray(ii, np.float64)
    sx, sy = (x1 - x0) / CROP_W, (y1 - y0) / CROP_H
    xs = np.r_[x0 + np.arange(CROP_W) * sx, float(x1)]
    ys = np.r_[y0 + np.arange(CROP_H) * sy, float(y1)]
    xi = np.minimum(np.floor(xs).astype(int), ii.shape[1] - 2)
    yi = np.minimum(np.floor(ys).astype(int), ii.shape[0] - 2)
    xf, yf = xs - xi, ys - yi
    a, a1 = ii[yi][:, xi], ii[yi][:, xi + 1]
    b, b1 = ii[yi + 1][:, xi], ii[yi + 1][:, xi + 1]
    top = a + xf * (a1 - a)
    bottom = b + xf * (b1 - b)
    s = top + yf[:, None] * (bottom - top)
    cells = (s[1:, 1:] - s[1:, :-1] - s[:-1, 1:] + s[:-1, :-1]) * (1.0 / (sx * sy))
    return np.clip(np.rint(cells), 0, 255).astype(np.uint8)


def crop_boxes(gray: np.ndarray, boxes, margin: float = MARGIN) -> np.ndarray:
    """(n, CROP_H, CROP_W) uint8: every box (left, top, right, bottom) with its margin, border replicated."""
    out = np.zeros((len(boxes), CROP_H, CROP_W), np.uint8)
    ii = None
    for i, (l, t, r, b) in enumerate(np.asarray(boxes, float).reshape(-1, 4)):
        mx, my = margin * (r - l), margin * (b - t)
        x0, y0, x1, y1 = (int(np.floor(v + 0.5)) for v in (l - mx, t - my, r + mx, b + my))
        if x1 - x0 < 2 or y1 - y0 < 2:
            continue
        if x0 >= 0 and y0 >= 0 and x1 <= gray.shape[1] and y1 <= gray.shape[0] and x1 - x0 >= CROP_W \
                and y1 - y0 >= CROP_H:
            if ii is None:
                ii = cv2.integral(gray, sdepth=cv2.CV_32S)
            out[i] = area_cells(ii, x0, y0, x1, y1)
            continue
        cx0, cy0 = min(max(x0, 0), gray.shape[1] - 1), min(max(y0, 0), gray.shape[0] - 1)
        cx1, cy1 = max(min(x1, gray.shape[1]), cx0 + 1), max(min(y1, gray.shape[0]), cy0 + 1)
        c = cv2.copyMakeBorder(gray[cy0:cy1, cx0:cx1], cy0 - y0, max(0, y1 - cy1), cx0 - x0, max(0, x1 - cx1),
                               cv2.BORDER_REPLICATE)
        out[i] = cv2.resize(c, (CROP_W, CROP_H), interpolation=cv2.INTER_AREA)
    return out


def crop_margin(params: dict) -> float:
    """The crop margin the network was trained with: its `crop_margin` (networks with the box output), else MARGIN."""
    return float(np.asarray(params["crop_margin"]).ravel()[0]) if "crop_margin" in params else MARGIN


def standardise(crops: np.ndarray) -> np.ndarray:
    """(n, 1, H, W) float32: z = (c - mean) / (std + 1), mean and std of each crop."""
    c = crops.astype(np.float32).reshape(len(crops), -1)
    m = c.mean(1, keepdims=True)
    s = c.std(1, keepdims=True)
    return ((c - m) / (s + 1.0)).reshape(len(crops), 1, CROP_H, CROP_W)


# ---- the network in numpy: the reference the ONNX graph, cv::dnn and the core are checked against ----

def _conv3x3_relu_pool(x: np.ndarray, w: np.ndarray, b: np.ndarray) -> np.ndarray:
    n, c, h, wd = x.shape
    xp = np.pad(x, ((0, 0), (0, 0), (1, 1), (1, 1)))
    cols = np.stack([xp[:, :, i:i + h, j:j + wd] for i in range(3) for j in range(3)], 2)  # n, c, 9, h, w
    y = np.einsum("nckhw,ock->nohw", cols, w.reshape(w.shape[0], c, 9)) + b[None, :, None, None]
    y = np.maximum(y, 0)
    return y.reshape(n, y.shape[1], h // 2, 2, wd // 2, 2).max((3, 5))


def forward(params: dict, z: np.ndarray, extra: np.ndarray, box: bool = False):
    """Probabilities (n,) for standardised crops z (n, 1, H, W) and raw extra features (n, 2); with `box`,
    also the box output (n, 4) (zeros for a network without one)."""
    a = z.astype(np.float32)
    for k in range(3):
        a = _conv3x3_relu_pool(a, params[f"conv{k}_w"], params[f"conv{k}_b"])
    e = (extra - params["extra_mean"]) * params["extra_scale"]
    h = np.maximum(np.c_[a.reshape(len(a), -1), e] @ params["dense_w"] + params["dense_b"], 0)
    p = 1 / (1 + np.exp(-(h @ params["out_w"] + params["out_b"]).ravel()))
    if not box:
        return p
    d = h @ params["box_w"] + params["box_b"] if "box_w" in params else np.zeros((len(h), 4), np.float32)
    return p, d


def refine(boxes, d) -> np.ndarray:
    """(n, 4) boxes (left, top, right, bottom) moved by the box output d (n, 4): each edge by d times the
    box's width (left, right) or height (top, bottom)."""
    b = np.asarray(boxes, np.float64).reshape(-1, 4)
    wh = np.c_[b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]]
    return b + np.asarray(d, np.float64).reshape(-1, 4) * wh[:, [0, 1, 0, 1]]


def offsets(boxes, targets) -> np.ndarray:
    """The box output that moves `boxes` onto `targets` (refine's inverse), (n, 4)."""
    b = np.asarray(boxes, np.float64).reshape(-1, 4)
    wh = np.c_[b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]]
    return (np.asarray(targets, np.float64).reshape(-1, 4) - b) / wh[:, [0, 1, 0, 1]]


# ---- ONNX ----

def save_onnx(params: dict, path: str, doc: str = "") -> None:
    """Write the network as ONNX (opset 11): inputs `crop` (N, 1, H, W) and `extra` (N, 2), outputs `p` (N, 1)
    and, when the parameters hold the box output (`box_w`, `box_b`), `box` (N, 4) and `margin` (N, 1): the crop
    margin it was trained with (`crop_margin`, default MARGIN), a constant the core reads once when it loads
    the file (cv::dnn exposes no other way to carry a number in the file).
    The extra features' standardisation is folded into the dense layer: W_e' = scale_e W_e,
    b' = b - (mean_e scale_e) . W_e."""
    # onnx is optional (pip install '.[train]'): imported only where a network is fitted, written or read
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    p = {k: np.asarray(v, np.float32) for k, v in params.items()}
    nflat = p["dense_w"].shape[0] - 2
    we = p["dense_w"][nflat:] * p["extra_scale"][:, None]
    dense_w = np.r_[p["dense_w"][:nflat], we]
    dense_b = p["dense_b"] - (p["extra_mean"] * p["extra_scale"]) @ p["dense_w"][nflat:]
    init = []
    nodes = []
    x = "crop"
    for k in range(3):
        init += [numpy_helper.from_array(p[f"conv{k}_w"], f"conv{k}_w"), numpy_helper.from_array(p[f"conv{k}_b"], f"conv{k}_b")]
        nodes += [helper.make_node("Conv", [x, f"conv{k}_w", f"conv{k}_b"], [f"c{k}"], kernel_shape=[3, 3],
                                   pads=[1, 1, 1, 1], strides=[1, 1]),
                  helper.make_node("Relu", [f"c{k}"], [f"r{k}"]),
                  helper.make_node("MaxPool", [f"r{k}"], [f"m{k}"], kernel_shape=[2, 2], strides=[2, 2])]
        x = f"m{k}"
    # W [flat, extra] + b as W_f flat + b + W_e extra (+ 0): cv::dnn's Concat cannot infer the shapes of a
    # 4-D branch flattened beside a 2-D input
    init += [numpy_helper.from_array(dense_w[:nflat].T.copy(), "dense_w"), numpy_helper.from_array(dense_b, "dense_b"),
             numpy_helper.from_array(dense_w[nflat:].T.copy(), "dense_we"),
             numpy_helper.from_array(np.zeros_like(dense_b), "dense_be"),
             numpy_helper.from_array(p["out_w"].reshape(-1, 1).T.copy(), "out_w"),
             numpy_helper.from_array(p["out_b"].reshape(1), "out_b")]
    nodes += [helper.make_node("Flatten", [x], ["flat"], axis=1),
              helper.make_node("Gemm", ["flat", "dense_w", "dense_b"], ["df"], transB=1),
              helper.make_node("Gemm", ["extra", "dense_we", "dense_be"], ["de"], transB=1),
              helper.make_node("Add", ["df", "de"], ["d"]),
              helper.make_node("Relu", ["d"], ["h"]),
              helper.make_node("Gemm", ["h", "out_w", "out_b"], ["logit"], transB=1),
              helper.make_node("Sigmoid", ["logit"], ["p"])]
    outputs = [helper.make_tensor_value_info("p", TensorProto.FLOAT, [1, 1])]
    if "box_w" in p:
        init += [numpy_helper.from_array(p["box_w"].T.copy(), "box_w"), numpy_helper.from_array(p["box_b"], "box_b")]
        init += [numpy_helper.from_array(np.zeros((1, len(p["dense_b"])), np.float32), "margin_w"),
                 numpy_helper.from_array(np.float32([crop_margin(p)]), "margin_b")]
        nodes += [helper.make_node("Gemm", ["h", "box_w", "box_b"], ["box"], transB=1),
                  helper.make_node("Gemm", ["h", "margin_w", "margin_b"], ["margin"], transB=1)]
        outputs += [helper.make_tensor_value_info("box", TensorProto.FLOAT, [1, 4]),
                    helper.make_tensor_value_info("margin", TensorProto.FLOAT, [1, 1])]
    graph = helper.make_graph(
        nodes, "headway_vehicle_verifier",
        [helper.make_tensor_value_info("crop", TensorProto.FLOAT, [1, 1, CROP_H, CROP_W]),
         helper.make_tensor_value_info("extra", TensorProto.FLOAT, [1, 2])],
        outputs, init)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="headway",
                              doc_string=doc)
    model.ir_version = 7
    onnx.checker.check_model(model)
    onnx.save(model, path)


def load_onnx(path: str) -> dict:
    """The parameters of a verifier ONNX written by `save_onnx` (standardisation folded: mean 0, scale 1)."""
    # onnx is optional (pip install '.[train]'): imported only where a network is fitted, written or read
    import onnx
    from onnx import numpy_helper

    w = {t.name: numpy_helper.to_array(t) for t in onnx.load(path).graph.initializer}
    if not {"conv0_w", "dense_w", "out_w"} <= set(w):
        raise ValueError(f"{path}: not a verifier network written by `headway train verifier --out X.onnx`")
    out = {k: w[k] for k in ("conv0_w", "conv0_b", "conv1_w", "conv1_b", "conv2_w", "conv2_b", "dense_b")}
    out.update(dense_w=np.r_[w["dense_w"].T, w["dense_we"].T], out_w=w["out_w"].ravel(), out_b=w["out_b"],
               extra_mean=np.zeros(2, np.float32), extra_scale=np.ones(2, np.float32))
    if "box_w" in w:
        out.update(box_w=w["box_w"].T.copy(), box_b=w["box_b"], crop_margin=w.get("margin_b", np.float32([MARGIN])))
    return out
