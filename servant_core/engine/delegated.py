"""An attribute of the engine that one of its parts keeps."""

from __future__ import annotations

from typing import Any


class Delegated:
    """An attribute kept by the part in the owner's attribute `part`, as `name` (by default the
    attribute's own name); read and written through the owner as if it were its own."""

    def __init__(self, part: str, name: str | None = None) -> None:
        self.part = part
        self.name = name

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = self.name or name

    def __get__(self, instance: Any, owner: type | None = None) -> Any:
        return self if instance is None else getattr(getattr(instance, self.part), str(self.name))

    def __set__(self, instance: Any, value: Any) -> None:
        setattr(getattr(instance, self.part), str(self.name), value)
