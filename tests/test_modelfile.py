import json

import numpy as np
import pytest

from servant_core.errors import ServantError
from servant_core.modelfile import VERSION, load_model, save_model
from servant_core.recognisers.paper import PaperVisualRecogniser
from servant_core.storage import atomic_save_npz


def fitted_visual() -> PaperVisualRecogniser:
    rng = np.random.default_rng(0)
    X = np.vstack([rng.normal(50, 5, (6, 3)), rng.normal(200, 5, (6, 3))]).astype(np.float32)
    return PaperVisualRecogniser(n_colours=1).fit(X, ["cafe"] * 6 + ["gym"] * 6)


def test_round_trip_gives_the_same_predictions(tmp_path):
    model = fitted_visual()
    path = save_model(tmp_path / "m.npz", {"visual": model})
    loaded = load_model(path)["visual"]
    X = np.array([[52, 49, 51], [198, 202, 200]], np.float32)
    assert loaded.predict(X).tolist() == ["cafe", "gym"]
    assert np.allclose(loaded.confidence(X), model.confidence(X))
    assert loaded.scenes_ == model.scenes_
    with np.load(path, allow_pickle=False) as npz:  # nothing in the file needs pickle
        header = json.loads(str(npz["header"]))
    assert header["version"] == VERSION and header["recognisers"]["visual"]["method"] == "paper"


def rewrite_header(path, change):
    with np.load(path, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    header = json.loads(str(arrays["header"]))
    change(header)
    arrays["header"] = np.array(json.dumps(header))
    atomic_save_npz(path, arrays)


def test_newer_version_is_refused(tmp_path):
    path = save_model(tmp_path / "m.npz", {"visual": fitted_visual()})
    rewrite_header(path, lambda h: h.update(version=VERSION + 1))
    with pytest.raises(ServantError, match="newer than this Servant reads"):
        load_model(path)


def test_unknown_method_is_refused(tmp_path):
    path = save_model(tmp_path / "m.npz", {"visual": fitted_visual()})
    rewrite_header(path, lambda h: h["recognisers"]["visual"].update(method="from-the-future"))
    with pytest.raises(ServantError, match="not known to this Servant"):
        load_model(path)


@pytest.mark.parametrize("content", [b"", b"garbage bytes", b"PK\x03\x04 truncated zip"])
def test_corrupt_files_are_refused(tmp_path, content):
    path = tmp_path / "m.npz"
    path.write_bytes(content)
    with pytest.raises(ServantError, match="not a Servant model file"):
        load_model(path)


def test_someone_elses_npz_and_pickles_are_refused(tmp_path):
    other = tmp_path / "other.npz"
    np.savez(other, weights=np.ones(3))
    with pytest.raises(ServantError, match="no valid header"):
        load_model(other)
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, header=np.array([{"format": "servant-model"}], dtype=object))
    with pytest.raises(ServantError, match="not a Servant model file"):
        load_model(pickled)


def test_object_arrays_are_never_written(tmp_path):
    with pytest.raises(TypeError, match="pickle"):
        atomic_save_npz(tmp_path / "x.npz", {"bad": np.array([{}], dtype=object)})
    assert list(tmp_path.iterdir()) == []


def test_missing_file_says_how_to_make_one(tmp_path):
    with pytest.raises(ServantError, match="servant train"):
        load_model(tmp_path / "nothing.npz")
