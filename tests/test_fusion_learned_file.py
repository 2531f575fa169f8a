"""The learned fusion's net in the model file: saved without pickle, checked strictly on load."""

import json

import numpy as np
import pytest

from servant_core.errors import ServantError
from servant_core.fusion.net import FLAGS, FusionNet
from servant_core.modelfile import load_model, load_model_and_fusion, save_model
from servant_core.recognisers.paper import PaperAcousticRecogniser, PaperVisualRecogniser
from servant_core.storage import atomic_save_npz
from tests.conftest import tone
from tests.test_fusion_learned import said
from tests.test_modelfile import fitted_visual


@pytest.fixture(scope="module")
def net():
    rng = np.random.default_rng(0)
    return FusionNet(hidden_layer_sizes=(8,), max_iter=200).fit(
        {"audio": said(rng, 60, 0.95), "image": said(rng, 60, 0.7)}
    )


def fitted_models():
    """An acoustic and a visual recogniser of the three scenes the net decides."""
    rng = np.random.default_rng(0)
    X = np.vstack([rng.normal(m, 5, (6, 3)) for m in (30, 120, 220)]).astype(np.float32)
    scenes = [s for s in ("cafe", "gym", "street") for _ in range(6)]
    visual = PaperVisualRecogniser(n_colours=1).fit(X, scenes)
    acoustic = PaperAcousticRecogniser(rate=8000, window_seconds=0.5, n_init=1)
    freqs = [f + d for f in (300, 1200, 3000) for d in (0, 10, 20, 30, 40, 50)]
    windows = np.stack([tone(f, 0.5, 8000) for f in freqs])
    return {"acoustic": acoustic.fit(acoustic.featurize(windows), scenes), "visual": visual}


def saved(tmp_path, net):
    return save_model(tmp_path / "m.npz", fitted_models(), fusion=net)


def test_round_trip_keeps_the_net_and_the_recognisers(tmp_path, net):
    path = saved(tmp_path, net)
    recognisers, loaded = load_model_and_fusion(path)
    assert set(recognisers) == set(load_model(path)) == {"acoustic", "visual"}
    X = np.random.default_rng(1).random((5, 2 * (3 + FLAGS)))
    assert np.array_equal(loaded.predict_proba(X), net.predict_proba(X))
    assert loaded.threshold_ == net.threshold_ and loaded.senses_ == ["audio", "image"]
    with np.load(path, allow_pickle=False) as npz:
        assert "fusion/coef_0" in npz.files
        assert json.loads(str(npz["header"]))["fusion"]["scenes"] == ["cafe", "gym", "street"]


def test_a_model_without_a_net_has_none(tmp_path):
    path = save_model(tmp_path / "m.npz", {"visual": fitted_visual()})
    assert load_model_and_fusion(path)[1] is None


def rewrite(path, header_change=None, array_change=None):
    with np.load(path, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    header = json.loads(str(arrays["header"]))
    if header_change:
        header_change(header["fusion"])
    if array_change:
        array_change(arrays)
    arrays["header"] = np.array(json.dumps(header))
    atomic_save_npz(path, arrays)


@pytest.mark.parametrize(
    "change",
    [
        lambda f: f["params"].update(hidden_layer_sizes=[9]),  # weights are 8 wide
        lambda f: f["params"].update(activation="softsign"),
        lambda f: f["params"].update(unheard_of=1),
        lambda f: f["params"].update(max_iter="400"),
        lambda f: f.update(threshold=1.5),
        lambda f: f.update(threshold=None),
        lambda f: f.update(scenes=["cafe", "gym"]),  # the output layer has three
        lambda f: f.update(scenes=["cafe", "cafe", "gym"]),
        lambda f: f.update(senses=["audio"]),
        lambda f: f.update(senses="audio"),
        lambda f: f.pop("params"),
        lambda f: f.clear(),
    ],
)
def test_a_doctored_header_is_refused_in_one_line(tmp_path, net, change):
    path = saved(tmp_path, net)
    rewrite(path, header_change=change)
    with pytest.raises(ServantError, match="damaged Servant model file.*fusion") as info:
        load_model_and_fusion(path)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    "change",
    [
        lambda a: a.update({"fusion/coef_0": a["fusion/coef_0"][:-1]}),
        lambda a: a.update({"fusion/intercept_1": np.full_like(a["fusion/intercept_1"], np.nan)}),
        lambda a: a.pop("fusion/coef_1"),
        lambda a: a.update({"fusion/coef_2": np.zeros((3, 3))}),
        lambda a: a.update({"fusion/coef_0": a["fusion/coef_0"].astype(np.complex64)}),
    ],
)
def test_wrong_weights_are_refused(tmp_path, net, change):
    path = saved(tmp_path, net)
    rewrite(path, array_change=change)
    with pytest.raises(ServantError, match="damaged Servant model file.*fusion"):
        load_model_and_fusion(path)


def test_every_number_of_the_header_beyond_floats_is_refused(tmp_path, net):
    """Issue 24 item 3: a 400-digit integer anywhere in the header (each parameter of the
    recogniser and of the net, `pool` and `hidden` included) is one ServantError, never an
    OverflowError."""
    from tests.test_fuzz_settings import number_paths

    path = saved(tmp_path, net)
    with np.load(path, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    header = json.loads(str(arrays["header"]))
    paths = number_paths(header)
    assert any("pool" in p for p in paths) and any("hidden_layer_sizes" in p for p in paths)
    for place in paths:
        changed = json.loads(json.dumps(header))
        node = changed
        for key in place[:-1]:
            node = node[key]
        node[place[-1]] = 10**400
        atomic_save_npz(path, {**arrays, "header": np.array(json.dumps(changed))})
        with pytest.raises(ServantError, match="m.npz"):
            load_model_and_fusion(path)


@pytest.mark.parametrize(
    "change,said",
    [
        (lambda f: f.update(senses=["audio", "video"]), "'video', a sense the model lacks"),
        (lambda f: f.update(scenes=["cafe", "gym", "office"]), "'office', a scene no recogniser"),
    ],
)
def test_a_net_that_does_not_fit_the_models_recognisers_is_refused(tmp_path, net, change, said):
    """Issue 24 item 7: a net naming `office` (or fusing a sense `video`) in a model whose
    recognisers know neither once announced `OfficeScene detected`."""
    path = saved(tmp_path, net)
    rewrite(path, header_change=change)
    with pytest.raises(ServantError, match=said):
        load_model_and_fusion(path)
    path = save_model(tmp_path / "visual-only.npz", {"visual": fitted_visual()}, fusion=net)
    with pytest.raises(ServantError, match="'audio', a sense the model lacks"):
        load_model_and_fusion(path)
