"""The suite's own schedule (tests/session_order.py): the longest modules it names exist and run first."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

from session_order import LONGEST_FIRST, longest_first

TESTS = Path(__file__).parent


def test_every_module_named_longest_first_exists():
    missing = [name for name in LONGEST_FIRST if not (TESTS / name).is_file()]
    assert missing == [], f"renamed or removed: update LONGEST_FIRST in tests/session_order.py {missing}"


def test_the_longest_modules_are_sorted_first_and_the_rest_keep_their_order():
    names = ["astro/test_a.py", LONGEST_FIRST[3], "vss/test_b.py", LONGEST_FIRST[0],
             "astro/test_a.py", LONGEST_FIRST[3]]
    items = [SimpleNamespace(path=TESTS / name, n=i) for i, name in enumerate(names)]
    longest_first(items)
    assert [item.n for item in items] == [3, 1, 5, 0, 2, 4]
