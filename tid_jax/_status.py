"""Outcome codes of the optimisers, with their messages: one shared type, so that every
result reports its status the same way (integer codes in an array, as NumPy, CSV and JSON
take them; `status_messages()` on the result explains them)."""

from types import MappingProxyType


class Outcomes:
    """The outcomes of one optimiser: `outcomes.name` is the integer code of the outcome
    `name` (codes in the order given, from 0, the first meaning success), and
    `outcomes.message(code)` what it means."""

    def __init__(self, **messages: str):
        self._codes = MappingProxyType({name: i for i, name in enumerate(messages)})
        self._messages = tuple(messages.values())

    def __getattr__(self, name: str) -> int:
        try:
            return self._codes[name]
        except KeyError:
            raise AttributeError(f"no outcome {name!r}; outcomes are {list(self._codes)}") from None

    def message(self, code) -> str:
        """The message of the outcome `code` (an integer, or a 0-d array of one)."""
        return self._messages[int(code)]

    def messages(self) -> dict[int, str]:
        """Every code with its message."""
        return dict(enumerate(self._messages))
