"""The options of `servant train | predict | eval | table`; the commands themselves are in
`servant_core.cli.train`, `.predict` and `.evaluation`, each imported only when one of its
commands runs: this module loads no library, so that each command's `--help` answers at once."""

from __future__ import annotations

import argparse
from pathlib import Path

from servant_core.choices import (
    ACOUSTIC_METHOD_NAMES,
    DEFAULT_POLICY,
    DEFAULT_RATE,
    DEFAULT_SHOTS,
    DEFAULT_WINDOW_SECONDS,
    EVAL_PROTOCOLS,
    FRESH_AUDIO_METHOD,
    FRESH_IMAGE_METHOD,
    IMAGE_TRAIN_FRACTION,
    POLICY_NAMES,
    VISUAL_METHOD_NAMES,
    FusionConfig,
)
from servant_core.cli import later, options

TRAIN = "servant_core.cli.train"
PREDICT = "servant_core.cli.predict"
EVALUATION = "servant_core.cli.evaluation"

IMAGE_METHOD_HELP = (
    "visual method (paper: the paper's dominant colours; effnet: EfficientNet-Lite2's ImageNet "
    "network, Apache-2.0; fisher-bovw: Servant's own, no network)"
)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `train`, `predict`, `eval audio|image|fusion` and `table` with their options; each
    runs its `cmd_*`, imported when it runs."""
    _register_train(subparsers.add_parser("train"))
    _register_predict(subparsers.add_parser("predict"))
    senses = subparsers.add_parser("eval").add_subparsers(
        dest="sense", metavar="SENSE", required=True
    )
    _register_eval_audio(
        senses.add_parser(
            "audio", help="acoustic recognition: temporal, recording, source or fewshot protocol"
        )
    )
    _register_eval_image(
        senses.add_parser("image", help="visual recognition: train library vs test library")
    )
    _register_eval_fusion(
        senses.add_parser("fusion", help="fused decisions over paired windows and pictures")
    )
    _register_table(subparsers.add_parser("table"))


def _register_train(train: argparse.ArgumentParser) -> None:
    """`servant train ROOT`: where the model goes, the methods, windows and learned fusion."""
    train.add_argument("root", type=Path, help="scene library: ROOT/<scene>/<recordings, pictures>")
    train.add_argument(
        "-o",
        "--output",
        type=Path,
        help="model file (default: the data dir's model.npz, which `servant` and `servant run` "
        "load at start)",
    )
    train.add_argument(
        "--force",
        action="store_true",
        help="replace the model `servant` loads when it exists (without -o); the old one is kept "
        "beside it as model.N.npz",
    )
    _method_options(train)
    _audio_options(train)
    _skip_bad_option(train)
    train.add_argument(
        "--learned-fusion",
        action="store_true",
        help="also train the learned fusion's net (for --policy learned) on the recognisers' "
        "held-out opinions; slower: each recogniser is refitted once per fold",
    )
    _json_option(train)
    train.set_defaults(handler=later(TRAIN, "cmd_train"))


def _register_predict(predict: argparse.ArgumentParser) -> None:
    """`servant predict MODEL`: a recording and/or pictures, and the fusion's options."""
    predict.add_argument("model", type=Path, help="model file from `servant train`")
    predict.add_argument("--audio", type=Path, help="a recording: each window is recognised")
    predict.add_argument("--image", type=Path, nargs="+", default=[], help="pictures, in order")
    _fusion_options(predict)
    _json_option(predict)
    predict.set_defaults(handler=later(PREDICT, "cmd_predict"))


def _register_eval_audio(audio: argparse.ArgumentParser) -> None:
    """`servant eval audio ROOT`: the protocol, the method and which scenes to keep."""
    audio.add_argument("root", type=Path, help="training recordings (and test, without --test)")
    _protocol_options(audio)
    audio.add_argument(
        "--method",
        choices=sorted(ACOUSTIC_METHOD_NAMES),
        default=FRESH_AUDIO_METHOD,
        help=(
            "acoustic method (paper: the paper's FFT K-Means; birdnet: BirdNET's network, "
            "non-commercial use only, CC BY-NC-SA 4.0; kmeans-encoder: Servant's own)"
        ),
    )
    audio.add_argument("--scenes", help="comma-separated scenes to keep (default: all)")
    audio.add_argument(
        "--min-recordings",
        type=options.bounded_int(1, 10_000),
        default=1,
        metavar="N",
        help="keep only the scenes with at least N recordings (default: %(default)s)",
    )
    _seeds_option(audio)
    _audio_options(audio)
    _skip_bad_option(audio)
    _json_option(audio)
    audio.set_defaults(handler=later(EVALUATION, "cmd_eval_audio"))


def _protocol_options(audio: argparse.ArgumentParser) -> None:
    """`eval audio`'s split of the recordings: `--protocol` and what some protocols take
    (`--groups`, `--shots`), or `--test` for another library."""
    audio.add_argument(
        "--protocol",
        choices=list(EVAL_PROTOCOLS),
        default="temporal",
        help="temporal: the first 60%% of each recording trains; recording: leave one recording "
        "out; source: leave one source out (the file name up to its first '-', or --groups); "
        "fewshot: the first k windows of each recording train",
    )
    audio.add_argument(
        "--groups",
        type=Path,
        metavar="FILE",
        help="source protocol: the group of each recording, one a line: PATH GROUP (PATH "
        "relative to ROOT); default: the file name up to its first '-'",
    )
    audio.add_argument(
        "--test",
        type=Path,
        help="test recordings from another library: train on all of ROOT, test on all of TEST",
    )
    audio.add_argument(
        "--shots",
        type=_shots,
        default=DEFAULT_SHOTS,
        help="fewshot: comma-separated windows per recording that train "
        f"(default: {','.join(map(str, DEFAULT_SHOTS))})",
    )


def _register_eval_image(image: argparse.ArgumentParser) -> None:
    """`servant eval image ROOT`: a test library or a split of ROOT, and the method."""
    image.add_argument("root", type=Path, help="training pictures")
    image.add_argument(
        "--test", type=Path, help="test pictures (default: split ROOT by file order)"
    )
    image.add_argument(
        "--split",
        type=options.open_fraction,
        default=IMAGE_TRAIN_FRACTION,
        help="without --test: fraction of each scene's files (by name) that train",
    )
    image.add_argument(
        "--method",
        choices=sorted(VISUAL_METHOD_NAMES),
        default=FRESH_IMAGE_METHOD,
        help=IMAGE_METHOD_HELP,
    )
    image.add_argument("--scenes", help="comma-separated scenes to keep (default: all)")
    _seeds_option(image)
    _skip_bad_option(image)
    _json_option(image)
    image.set_defaults(handler=later(EVALUATION, "cmd_eval_image"))


def _register_eval_fusion(fusion: argparse.ArgumentParser) -> None:
    """`servant eval fusion ROOT`: the methods, the fusion's options and a sense to withhold."""
    fusion.add_argument("root", type=Path, help="library with recordings and pictures per scene")
    _method_options(fusion)
    fusion.add_argument("--scenes", help="comma-separated scenes to keep (default: all paired)")
    _fusion_options(fusion)
    fusion.add_argument(
        "--drop-sense",
        choices=("audio", "image"),
        help="withhold this sense at test time (a broken microphone or camera)",
    )
    _seeds_option(fusion)
    _skip_bad_option(fusion)
    _json_option(fusion)
    fusion.set_defaults(handler=later(EVALUATION, "cmd_eval_fusion"))


def _register_table(table: argparse.ArgumentParser) -> None:
    """`servant table LIBRARY`: the paper's methods by default, an optional test library."""
    table.add_argument("library", type=Path, help="scene library with recordings and pictures")
    table.add_argument("--test", type=Path, help="take the test recording and picture from here")
    table.add_argument(
        "--scenes", help="comma-separated scenes (default: all with sound and pictures)"
    )
    _method_options(table, paper=True)
    _skip_bad_option(table)
    _json_option(table)
    table.set_defaults(handler=later(EVALUATION, "cmd_table"))


def _json_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")


def _skip_bad_option(parser: argparse.ArgumentParser) -> None:
    # one rule for every command that reads a library: a damaged file stops it, by default
    parser.add_argument(
        "--skip-bad",
        action="store_true",
        help="skip unreadable or damaged files (with a warning) instead of stopping",
    )


def _method_options(parser: argparse.ArgumentParser, paper: bool = False) -> None:
    """`--audio-method`, `--image-method`: the better methods by default (the engine's choice
    for fresh models), the paper's for `table`, which reproduces the paper."""
    parser.add_argument(
        "--audio-method",
        choices=sorted(ACOUSTIC_METHOD_NAMES),
        default="paper" if paper else FRESH_AUDIO_METHOD,
        help=(
            "acoustic method (paper: the paper's FFT K-Means; birdnet: BirdNET's network, "
            "non-commercial use only, CC BY-NC-SA 4.0; kmeans-encoder: Servant's own)"
        ),
    )
    parser.add_argument(
        "--image-method",
        choices=sorted(VISUAL_METHOD_NAMES),
        default="paper" if paper else FRESH_IMAGE_METHOD,
        help=IMAGE_METHOD_HELP,
    )


def _seeds_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--seeds",
        type=options.bounded_int(1, 100),
        default=1,
        help="repeat over random states 0..N-1 and report mean and spread (default: %(default)s, "
        "the method's own random state)",
    )


def _shots(text: str) -> tuple[int, ...]:
    try:
        shots = tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError:
        shots = ()
    if not shots or min(shots) < 1:
        raise argparse.ArgumentTypeError(
            f"{text!r}: give whole numbers of windows, each at least 1 (e.g. 1,3,10)"
        )
    return shots


def _audio_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--rate",
        type=options.sample_rate,
        help=f"model sample rate (Hz); default: the method's own ({DEFAULT_RATE} for paper)",
    )
    parser.add_argument(
        "--window",
        type=options.window_seconds,
        default=DEFAULT_WINDOW_SECONDS,
        help="window length (s)",
    )


def _fusion_options(parser: argparse.ArgumentParser) -> None:
    defaults = FusionConfig()
    parser.add_argument(
        "--policy",
        choices=sorted(POLICY_NAMES),
        default=DEFAULT_POLICY,
        help="sequential: the paper's (hear, then look); parallel: both senses at once; "
        "learned: a small neural net over every sense's probabilities (parallel without one)",
    )
    parser.add_argument(
        "--acoustic-window",
        type=options.fusion_seconds,
        default=defaults.acoustic_window_s,
        help="seconds an acoustic prediction waits for pictures to agree",
    )
    parser.add_argument(
        "--confirm-window",
        type=options.fusion_seconds,
        default=defaults.confirm_window_s,
        help="seconds within which the agreeing pictures must fall",
    )
    parser.add_argument(
        "--pictures",
        type=options.picture_count,
        default=defaults.pictures_needed,
        help="agreeing pictures needed to detect a scene",
    )
