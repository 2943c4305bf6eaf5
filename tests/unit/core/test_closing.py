"""`Closing`: leaving a `with` block closes the resource, however the block ends."""

from __future__ import annotations

import pytest

from twin.core.closing import Closing


class Counted(Closing):
    def __init__(self) -> None:
        self.closed = 0

    def close(self) -> None:
        self.closed += 1


def test_with_returns_the_object_and_closes_it_once() -> None:
    thing = Counted()
    with thing as entered:
        assert entered is thing and thing.closed == 0
    assert thing.closed == 1


def test_an_exception_in_the_block_still_closes_and_propagates() -> None:
    thing = Counted()
    with pytest.raises(KeyboardInterrupt), thing:
        raise KeyboardInterrupt
    assert thing.closed == 1


def test_a_subclass_without_close_is_refused_on_leaving() -> None:
    with pytest.raises(NotImplementedError), Closing():
        pass
