"""Peak memory and time of one `servant predict` call on the worst files at the boundary.

Issue 13's target: any single CLI call on a file under 10 MB stays under 1 GB. Each case runs the
real console script in a child process; its peak resident size comes from `os.wait4`.

    .venv/bin/python bench/boundary_memory.py
"""

from __future__ import annotations

import io
import os
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

import cv2
import numpy as np
import soundfile as sf

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from servant_core.modelfile import save_model  # noqa: E402
from servant_core.recognisers.paper import (  # noqa: E402
    PaperAcousticRecogniser,
    PaperVisualRecogniser,
)
from tests.cli_harness import zip_bomb  # noqa: E402


def model(folder: Path) -> Path:
    rng = np.random.default_rng(0)
    acoustic = PaperAcousticRecogniser(n_init=1)
    windows = 0.1 * rng.standard_normal((4, 44100 * 5), dtype=np.float32)
    acoustic.fit(acoustic.featurize(windows), ["cafe", "cafe", "gym", "gym"])
    visual = PaperVisualRecogniser(n_init=1)
    pictures = [np.full((8, 8, 3), v, np.uint8) for v in (20, 30, 200, 210)]
    visual.fit(visual.featurize(pictures), ["cafe", "cafe", "gym", "gym"])
    return save_model(folder / "model.npz", {"acoustic": acoustic, "visual": visual})


def png_claiming(width: int, height: int) -> bytes:
    data = bytearray(cv2.imencode(".png", np.zeros((4, 4, 3), np.uint8))[1].tobytes())
    data[16:20], data[20:24] = width.to_bytes(4, "big"), height.to_bytes(4, "big")
    data[29:33] = zlib.crc32(bytes(data[12:29])).to_bytes(4, "big")
    return bytes(data)


def cases(folder: Path) -> list[tuple[str, str, Path]]:
    out: list[tuple[str, str, Path]] = []
    long = folder / "ten-minutes-192k.flac"
    with sf.SoundFile(long, "w", 192000, 1, format="FLAC") as handle:
        block = (0.001 * np.sin(np.arange(192000) / 10)).astype(np.float32)
        for _ in range(599):
            handle.write(block)
    out.append(("599 s of 192 kHz FLAC", "--audio", long))
    buffer = io.BytesIO()
    sf.write(buffer, np.zeros(16000, np.float32), 8000, format="WAV", subtype="PCM_16")
    wav = bytearray(buffer.getvalue())
    wav[24:28] = (1).to_bytes(4, "little")
    (folder / "one-hz.wav").write_bytes(bytes(wav))
    out.append(("2 s WAV whose header says 1 Hz", "--audio", folder / "one-hz.wav"))
    (folder / "giga.png").write_bytes(png_claiming(40000, 40000))
    out.append(("PNG header claiming 40000x40000", "--image", folder / "giga.png"))
    (folder / "49mpx.png").write_bytes(png_claiming(7000, 7000))
    out.append(("PNG header claiming 7000x7000 (allowed)", "--image", folder / "49mpx.png"))
    return out


def run(*argv: str) -> tuple[int, float, float, str]:
    start = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        child = subprocess.Popen(
            [sys.executable, "-m", "servant_tui", *argv],
            stdout=subprocess.DEVNULL,
            stderr=err,
            cwd=REPO,
        )
        _, status, usage = os.wait4(child.pid, 0)
        child.returncode = 0
        err.seek(0)
        line = err.read().decode(errors="replace").strip().splitlines()
    return (
        os.waitstatus_to_exitcode(status),
        usage.ru_maxrss / 1024,
        time.perf_counter() - start,
        line[-1][:90] if line else "",
    )


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        good = model(folder)
        picture = folder / "p.png"
        cv2.imwrite(str(picture), np.full((8, 8, 3), 25, np.uint8))
        rows = [(what, good, option, path) for what, option, path in cases(folder)]
        rows.append(
            (
                "npz with a 300 MB member (0.3 MB file)",
                zip_bomb(folder / "bomb.npz"),
                "--image",
                picture,
            )
        )
        print(f"{'case':42} {'file MB':>8} {'exit':>4} {'peak MB':>8} {'s':>6}  stderr")
        for what, model_path, option, path in rows:
            size = (path if model_path == good else model_path).stat().st_size / 1e6
            code, peak, seconds, line = run("predict", str(model_path), option, str(path))
            print(f"{what:42} {size:8.2f} {code:4d} {peak:8.0f} {seconds:6.1f}  {line}")


if __name__ == "__main__":
    main()
