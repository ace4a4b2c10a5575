"""One mechanism for the attributes a holder reads through to one of its parts (a pipeline's
counters of its commit stage, a service of one structure's parts of that structure)."""

from __future__ import annotations

from typing import Any, Generic, TypeVar, overload

__all__ = ["ReadThrough"]

T = TypeVar("T")


class ReadThrough(Generic[T]):
    """A read-only attribute: ``holder.<name>`` is ``holder.<via>.<name>`` (``attr``: another name).

    >>> class Stage:
    ...     windows = 3
    >>> class Pipeline:
    ...     stage = Stage()
    ...     windows: ReadThrough[int] = ReadThrough("stage")
    >>> Pipeline().windows
    3
    """

    def __init__(self, via: str, attr: str | None = None) -> None:
        self.via, self.attr = via, attr

    def __set_name__(self, owner: type, name: str) -> None:
        self.attr = self.attr or name

    @overload
    def __get__(self, holder: None, owner: type | None = None) -> ReadThrough[T]: ...
    @overload
    def __get__(self, holder: object, owner: type | None = None) -> T: ...

    def __get__(self, holder: Any, owner: type | None = None) -> Any:
        if holder is None:
            return self
        return getattr(getattr(holder, self.via), self.attr)  # type: ignore[arg-type]

    def __set__(self, holder: object, value: T) -> None:
        raise AttributeError(f"{self.attr} is read through {self.via}: set it there")
