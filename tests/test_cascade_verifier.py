"""The verifier's network (app/train/verifier.py): fitted by the project's own code, deterministic by
seed, written and read back with cv2.FileStorage, and it separates what can be separated."""
from __future__ import annotations

import numpy as np
import pytest

from app.train.verifier import Mlp, fit_mlp


def _xor_like(rng, n):
    """Two classes no linear rule separates: vehicle when the first two features share their sign."""
    x = rng.normal(0, 1, (n, 6)).astype(np.float32)
    y = np.where(x[:, 0] * x[:, 1] > 0, 1.0, -1.0)
    return x, y


def test_network_separates_a_nonlinear_problem_and_is_deterministic():
    rng = np.random.default_rng(0)
    x, y = _xor_like(rng, 4000)
    xt, yt = _xor_like(rng, 1000)
    m = fit_mlp(x, y, hidden=16, epochs=20, decay=1e-4, seed=0, lr=1e-2)
    acc = ((m.logit(xt) > 0) == (yt > 0)).mean()
    assert acc >= 0.9  # a linear rule gets ~0.5 here
    again = fit_mlp(x, y, hidden=16, epochs=20, decay=1e-4, seed=0, lr=1e-2)
    assert np.array_equal(m.w1, again.w1) and m.b2 == again.b2


def test_model_file_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    x, y = _xor_like(rng, 500)
    m = fit_mlp(x, y, hidden=8, epochs=2, decay=1e-4, seed=0)
    m.save(str(tmp_path / "v.yml"))
    back = Mlp.load(str(tmp_path / "v.yml"))
    assert np.allclose(back.probability(x), m.probability(x), atol=1e-6)
    (tmp_path / "bad.yml").write_text("%YAML:1.0\n---\nbias: 1.\n")
    with pytest.raises(ValueError, match="headway train verifier"):
        Mlp.load(str(tmp_path / "bad.yml"))
