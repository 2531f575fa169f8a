"""The layers of servant_core, read from the source: every `import` and `from … import` of every
module (those inside functions too, which load lazily) is checked against the order below.

servant_core never imports servant_tui, Textual or Rich (`test_core_without_textual.py` proves
the Textual half at run time as well). Within servant_core, a module imports only from its own
unit (a package, or a top-level module) or from a unit in a layer below its own; units in the
same layer are siblings and do not import each other. Bottom first:

1. leaves, importing nothing of servant_core: errors, numbers, json_objects, choices, senses,
   events, threads, progress, perceptron (a small net's forward pass)
2. storage (atomic writes, the data folders)
3. settings, place_names, pty_port, serial_port
4. event_text | log_news: the words front ends share for events; which events a log says
5. features, audio (acoustic and visual vectors; reading and resampling sound)
6. library (the scene library on disk: which files are recordings, pictures and sample logs)
7. capture | servo: the device packages, the senses' sources and the arm's link; each opens
   serial ports through serial_port, neither knows the other
8. recognisers (sound, pictures, and the sample senses of the sensor board in capture)
9. fusion (the policies deciding from the recognisers' opinions)
10. actions (teach records and the scene → pose learner, acting on a decision)
11. demo | modelfile: the demo's synthesised places, arm and sensor board (their sources in
    capture, the recognisers fitted on them, the emulated controller in servo); the model file
    (the fitted recognisers and the learned fusion net, so above both)
12. engine (owns all of the above: runs the senses, decides, acts)
13. evaluate | evaluate_motion: the evaluation protocols (evaluate_motion measures the motion
    sense on the demo's synthesised walks when no logs are given)
14. cli (the headless commands)

A module this list does not place fails the test until it is placed; an import against it fails
unless `EXCEPTIONS` names it with its reason.
"""

from __future__ import annotations

import ast
from pathlib import Path

from tests.conftest import REPO

CORE = "servant_core"
FORBIDDEN = ("servant_tui", "textual", "rich")
LAYERS: tuple[tuple[str, ...], ...] = (
    (
        "errors",
        "numbers",
        "json_objects",
        "choices",
        "senses",
        "events",
        "threads",
        "progress",
        "perceptron",
    ),
    ("storage",),
    ("settings", "place_names", "pty_port", "serial_port"),
    ("event_text", "log_news"),
    ("features", "audio"),
    ("library",),
    ("capture", "servo"),
    ("recognisers",),
    ("fusion",),
    ("actions",),
    ("demo", "modelfile"),
    ("engine",),
    ("evaluate", "evaluate_motion"),
    ("cli",),
)
LAYER_OF = {unit: rank for rank, units in enumerate(LAYERS) for unit in units}
# Arrows against the order kept for now, each with its reason: (importer, imported) -> why.
# None today: capture's sensor emulator moved to demo/, the serial port's opening below servo and
# capture, and the perceptron's forward pass below fusion and actions (issue 40).
EXCEPTIONS: dict[tuple[str, str], str] = {}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_in(source: str, module: str, package: bool = False) -> set[str]:
    """Every module the source of `module` imports, at any depth of its code (inside functions
    too), relative imports resolved; `package`: the source is the package's `__init__`."""
    parts = module.split(".") if package else module.split(".")[:-1]
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level:
            base = parts[: len(parts) - node.level + 1]
            found.add(".".join([*base, node.module] if node.module else base))
        elif isinstance(node, ast.ImportFrom) and node.module:
            found.add(node.module)
    return found


def unit_of(module: str) -> str | None:
    """`servant_core.fusion.learned` -> "fusion"; the package itself -> None."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def core_imports() -> dict[str, set[str]]:
    return {
        module_name(path): imports_in(
            path.read_text(encoding="utf-8"), module_name(path), path.name == "__init__.py"
        )
        for path in sorted((REPO / CORE).rglob("*.py"))
    }


def against_the_order(imports: dict[str, set[str]]) -> list[tuple[str, str]]:
    """(importer, imported) pairs of servant_core that point up, or sideways between siblings."""
    arrows = []
    for module, names in imports.items():
        here = unit_of(module)
        for name in sorted(n for n in names if n.split(".")[0] == CORE):
            there = unit_of(name)
            if here is None or there is None or here == there:
                continue
            if LAYER_OF[there] >= LAYER_OF[here]:
                arrows.append((module, name))
    return arrows


def test_servant_core_never_imports_the_front_end():
    bad = [
        (module, name)
        for module, names in core_imports().items()
        for name in names
        if name.split(".")[0] in FORBIDDEN
    ]
    assert not bad, f"servant_core imports the front end's packages: {bad}"


def test_every_unit_of_servant_core_has_a_layer():
    units = {unit_of(module) for module in core_imports()} - {None}
    assert not units - set(LAYER_OF), f"place these in LAYERS: {sorted(units - set(LAYER_OF))}"
    assert not set(LAYER_OF) - units, f"gone from servant_core: {sorted(set(LAYER_OF) - units)}"


def test_no_import_points_up_or_sideways():
    arrows = [a for a in against_the_order(core_imports()) if a not in EXCEPTIONS]
    assert not arrows, "imports against the layers (tests/test_layers.py):\n" + "\n".join(
        f"  {module} -> {name}" for module, name in arrows
    )


def test_every_exception_is_still_needed():
    stale = set(EXCEPTIONS) - set(against_the_order(core_imports()))
    assert not stale, f"no longer imported, drop from EXCEPTIONS: {sorted(stale)}"


def test_the_check_sees_an_import_inside_a_function():
    """An upward arrow hidden in a function body, or written relative, is an arrow all the same."""
    source = "def late():\n    from ..engine import core\n    import textual.app\n"
    imports = {"servant_core.fusion.probe": imports_in(source, "servant_core.fusion.probe")}
    assert against_the_order(imports) == [("servant_core.fusion.probe", "servant_core.engine")]
    assert "textual.app" in imports["servant_core.fusion.probe"]
