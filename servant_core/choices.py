"""What the command line offers to choose, by name, and the defaults: no library is imported
here (numpy, scikit-learn, OpenCV), so that `servant <command> --help` answers at once.

The registries that map these names to classes (`recognisers.ACOUSTIC_METHODS`, `fusion.POLICIES`)
live beside the classes; a test holds them to the names here.
"""

from __future__ import annotations

from dataclasses import dataclass

DEFAULT_RATE = 44100
DEFAULT_WINDOW_SECONDS = 5.0
# What a recording or a model may claim. Real recordings are 8 kHz (telephone) to 192 kHz
# (studio); a header outside that is damaged.
MIN_RATE = 8000
MAX_RATE = 192000
MIN_WINDOW_SECONDS = 0.5
MAX_WINDOW_SECONDS = 60.0

ACOUSTIC_METHOD_NAMES = ("paper", "codebook", "kmeans-encoder", "birdnet")
VISUAL_METHOD_NAMES = ("paper", "bovw", "softbovw", "fisher-bovw", "effnet")
# What a retrain fits for sound and pictures when there is no recogniser yet, and what `servant
# train` and the demo use: the methods beyond the paper that lead on the wearer's walk and every
# protocol (docs/research.md). A sample sense has one method (`senses.SAMPLE_METHOD`).
FRESH_AUDIO_METHOD = "birdnet"
FRESH_IMAGE_METHOD = "effnet"

POLICY_NAMES = ("sequential", "parallel", "learned")
# What `servant run`, `predict`, `eval fusion` and the app fuse with unless told otherwise (the
# paper's own rule, `sequential`, is what `--paper` and `table` reproduce).
DEFAULT_POLICY = "parallel"


@dataclass(frozen=True)
class FusionConfig:
    acoustic_window_s: float = 30.0
    confirm_window_s: float = 20.0
    pictures_needed: int = 3
    picture_interval_s: float = 2.0


# `servant eval audio --protocol`
EVAL_PROTOCOLS = ("temporal", "recording", "source", "fewshot")
DEFAULT_SHOTS = (1, 2, 3, 5, 10)
IMAGE_TRAIN_FRACTION = 0.7
