"""Evaluation protocols (DESIGN.md) and the paper's tables, one module a protocol or a score.

`splits`: which windows and pictures train and which test, each protocol's folds; `metrics`:
the figures of pooled predictions, over random states; `audio` and `image`: scoring one sense's
recogniser; `paired`: both recognisers fitted on one library; `fusion`: scoring a fusion policy;
`tables`: the paper's Tables I and II. The names callers use are re-exported here.
"""

from __future__ import annotations

from servant_core.choices import IMAGE_TRAIN_FRACTION
from servant_core.evaluate.audio import evaluate_audio, evaluate_windows, featurize_library_audio
from servant_core.evaluate.fusion import (
    FusionSetup,
    Said,
    evaluate_fusion,
    fusion_setup,
    run_encounter,
    run_fusion,
    said_of,
    score_fusion,
    score_learned,
)
from servant_core.evaluate.image import evaluate_image
from servant_core.evaluate.metrics import LOG_EPS, Predictions, over_seeds, scores, seeded_params
from servant_core.evaluate.paired import PairedFit, fit_paired
from servant_core.evaluate.splits import (
    PROTOCOLS,
    TAUGHT,
    TRAIN_FRACTION,
    AudioPlan,
    audio_plans,
    fewshot_split,
    file_order_split,
    read_groups,
    recording_groups,
    source_of,
    temporal_split,
)
from servant_core.evaluate.tables import format_tables, paper_tables

__all__ = [
    "IMAGE_TRAIN_FRACTION",
    "LOG_EPS",
    "PROTOCOLS",
    "TAUGHT",
    "TRAIN_FRACTION",
    "AudioPlan",
    "FusionSetup",
    "PairedFit",
    "Predictions",
    "Said",
    "audio_plans",
    "evaluate_audio",
    "evaluate_fusion",
    "evaluate_image",
    "evaluate_windows",
    "featurize_library_audio",
    "fewshot_split",
    "file_order_split",
    "fit_paired",
    "format_tables",
    "fusion_setup",
    "over_seeds",
    "paper_tables",
    "read_groups",
    "recording_groups",
    "run_encounter",
    "run_fusion",
    "said_of",
    "score_fusion",
    "score_learned",
    "scores",
    "seeded_params",
    "source_of",
    "temporal_split",
]
