"""A boosted cascade of Haar stumps: its own evaluator and OpenCV's cascade XML (the format OpenCV 4's
`CascadeClassifier` reads: <cascade> with stageType BOOST, featureType HAAR, stumps as internalNodes
"0 -1 feature threshold" and leafValues "left right").

A window passes stage s when sum_i (f_i < t_i ? left_i : right_i) >= T_s, summed in double precision over
single-precision leaves as OpenCV does; its score is the last stage's sum.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from .haar import FeatureSet, integrals, responses, variance_norm


# OpenCV lowers every stage threshold by this when it reads the XML (Data::read: THRESHOLD_EPS = 1e-5f).
THRESHOLD_EPS = np.float32(1e-5)


def stage_passes(sums: np.ndarray, threshold: float) -> np.ndarray:
    """OpenCV's test: sum (double) >= (float)threshold - THRESHOLD_EPS, the difference in single precision."""
    return sums >= np.float32(np.float32(threshold) - THRESHOLD_EPS)


@dataclass
class Stage:
    features: list[int] = field(default_factory=list)   # index into the FeatureSet, one per stump
    thresholds: list[float] = field(default_factory=list)  # float32 values: left when f < threshold
    left: list[float] = field(default_factory=list)
    right: list[float] = field(default_factory=list)
    threshold: float = 0.0                               # float32: pass when the sum >= threshold

    def sums(self, values: np.ndarray) -> np.ndarray:
        """Stage sums of windows given (n_stumps, N) responses of this stage's features."""
        t = np.asarray(self.thresholds, np.float32)[:, None]
        leaves = np.where(values < t, np.asarray(self.left, np.float32)[:, None],
                          np.asarray(self.right, np.float32)[:, None]).astype(np.float64)
        total = np.zeros(values.shape[1])
        for row in leaves:      # sequential, as OpenCV adds them
            total += row
        return total


@dataclass
class Cascade:
    width: int
    height: int
    stages: list[Stage] = field(default_factory=list)
    params: dict = field(default_factory=dict)           # training parameters, written to the XML

    def evaluate(self, fs: FeatureSet, patches: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For (N, H, W) uint8 windows: passed (bool), stages passed (int), last stage's sum (float)."""
        norm, valid = variance_norm(patches)
        ii = integrals(patches)
        alive = valid.copy()
        depth = np.zeros(len(patches), np.int32)
        score = np.zeros(len(patches))
        for si, st in enumerate(self.stages):
            ids = np.flatnonzero(alive)
            if not len(ids):
                break
            vals = responses(fs, np.asarray(st.features), ii[ids], norm[ids])
            s = st.sums(vals)
            ok = stage_passes(s, st.threshold)
            score[ids] = s
            depth[ids[ok]] = si + 1
            alive[ids[~ok]] = False
        return alive, depth, score

    def to_xml(self, fs: FeatureSet) -> str:
        used = sorted({f for st in self.stages for f in st.features})
        remap = {f: i for i, f in enumerate(used)}
        g = lambda v: "%.9g" % float(np.float32(v))  # noqa: E731  float32 round trip
        out = ['<?xml version="1.0"?>', "<opencv_storage>", "<cascade>",
               "  <stageType>BOOST</stageType>", "  <featureType>HAAR</featureType>",
               f"  <height>{self.height}</height>", f"  <width>{self.width}</width>", "  <stageParams>",
               f"    <boostType>{'DAB' if self.params.get('booster') == 'discrete' else 'GAB'}</boostType>",
               f"    <minHitRate>{self.params.get('min_hit_rate', 0.995)}</minHitRate>",
               f"    <maxFalseAlarm>{self.params.get('max_false_alarm', 0.5)}</maxFalseAlarm>",
               "    <weightTrimRate>1.</weightTrimRate>", "    <maxDepth>1</maxDepth>",
               f"    <maxWeakCount>{max([len(s.features) for s in self.stages] or [1])}</maxWeakCount></stageParams>",
               "  <featureParams>", "    <maxCatCount>0</maxCatCount>", "    <featSize>1</featSize>",
               "    <mode>ALL</mode></featureParams>", f"  <stageNum>{len(self.stages)}</stageNum>", "  <stages>"]
        for si, st in enumerate(self.stages):
            out += [f"    <!-- stage {si} -->", "    <_>", f"      <maxWeakCount>{len(st.features)}</maxWeakCount>",
                    f"      <stageThreshold>{g(st.threshold)}</stageThreshold>", "      <weakClassifiers>"]
            for f, t, lv, rv in zip(st.features, st.thresholds, st.left, st.right):
                out += ["        <_>", f"          <internalNodes>0 -1 {remap[f]} {g(t)}</internalNodes>",
                        f"          <leafValues>{g(lv)} {g(rv)}</leafValues></_>"]
            out += ["      </weakClassifiers></_>"]
        out += ["  </stages>", "  <features>"]
        for f in used:
            out.append("    <_>")
            out.append("      <rects>")
            for (x, y, w, h), wt in zip(fs.rects[f], fs.weights[f]):
                if wt != 0:
                    out.append(f"        <_>{x} {y} {w} {h} {g(wt)}</_>")
            out += ["      </rects>", "      <tilted>0</tilted></_>"]
        out += ["  </features>", "</cascade>", "</opencv_storage>", ""]
        return "\n".join(out)

    @staticmethod
    def from_xml(fs: FeatureSet, path: str) -> "Cascade":
        """A cascade this trainer wrote (to train more stages on it): features mapped back to `fs`."""
        root = ET.parse(path).getroot().find("cascade")
        if root is None or root.findtext("featureType", "").strip() != "HAAR":
            raise ValueError(f"{path}: not an OpenCV HAAR cascade XML")
        w, h = int(root.findtext("width")), int(root.findtext("height"))
        if (w, h) != (fs.width, fs.height):
            raise ValueError(f"{path}: window {w}x{h}, not the {fs.width}x{fs.height} being trained")
        index = {}
        for i, (rs, ws) in enumerate(zip(fs.rects, fs.weights)):
            index[tuple((*r, float(wt)) for r, wt in zip(rs.tolist(), ws.tolist()) if wt != 0)] = i
        feats = []
        for f in root.find("features"):
            key = tuple((*map(int, r.text.split()[:4]), float(np.float32(r.text.split()[4]))) for r in f.find("rects"))
            if key not in index or f.findtext("tilted", "0").strip() != "0":
                raise ValueError(f"{path}: feature {key} is not one of the upright Haar features this trainer uses")
            feats.append(index[key])
        c = Cascade(w, h)
        for node in root.find("stages"):
            f32 = lambda v: float(np.float32(v))  # noqa: E731  the values were float32 when written
            st = Stage(threshold=f32(node.findtext("stageThreshold")))
            for weak in node.find("weakClassifiers"):
                _, _, fi, t = weak.findtext("internalNodes").split()
                lv, rv = weak.findtext("leafValues").split()
                st.features.append(feats[int(fi)])
                st.thresholds.append(f32(t))
                st.left.append(f32(lv))
                st.right.append(f32(rv))
            c.stages.append(st)
        return c

    def save(self, fs: FeatureSet, path: str) -> None:
        with open(path, "w") as fh:
            fh.write(self.to_xml(fs))
