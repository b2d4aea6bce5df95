"""A registry of declarations found by name (the phase kinds, the responses)."""

from __future__ import annotations

from typing import Generic, TypeVar

T = TypeVar("T")


class Registry(dict, Generic[T]):
    """Declarations by their ``name``, in declaration order; ``what`` names them in errors
    (``phase kind``, ``response``) and ``reserved`` are names none may take."""

    def __init__(self, what: str, plural: str, reserved: tuple[str, ...] = ()):
        super().__init__()
        self.what, self.plural, self.reserved = what, plural, reserved

    def add(self, item: T) -> T:
        """Make ``item`` known by its name (a second of the same name is refused)."""
        name = item.name
        if name in self or name in self.reserved:
            raise ValueError(f"{self.what} {name!r} is declared already")
        self[name] = item
        return item

    def find(self, name: str) -> T:
        """The declaration called ``name``.

        Raises
        ------
        KeyError
            Naming the declared ones.
        """
        try:
            return self[name]
        except KeyError:
            raise KeyError(f"no {self.what} {name!r}; the {self.plural} are "
                           f"{', '.join(self)}") from None
