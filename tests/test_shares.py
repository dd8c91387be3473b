"""CI's two shares of the long tests (HYDROBUCKLE_TEST_SHARE, tests/conftest.py): every listed test
exists, each test is in one share, tests sharing a module fixture share a share, and the two take
about the same time."""

import re
from pathlib import Path

import conftest
from conftest import rank_local


@rank_local
def test_every_listed_long_test_exists():
    """A renamed or removed test left in the list would no longer be shared (it would run on both stacks)."""
    here = Path(conftest.__file__).parent
    missing = []
    for nodeid in conftest.listed_seconds():
        path, name = nodeid.split("::", 1)
        function = name.split("[", 1)[0]
        source = (here.parent / path).read_text() if (here.parent / path).is_file() else ""
        if not re.search(rf"^def {re.escape(function)}\(", source, re.M):
            missing.append(nodeid)
    assert missing == []


@rank_local
def test_the_shares_split_the_long_tests_evenly_and_keep_fixture_mates_together(request):
    items = request.session.items
    seconds = conftest.listed_seconds()
    shares = conftest.long_test_shares(items, 2, seconds)
    assert set(shares.values()) <= {1, 2}
    for item in items:  # fixture mates: one share
        mates = [other for other in items if conftest._module_fixtures(item) & conftest._module_fixtures(other)]
        assert {shares.get(m.nodeid) for m in mates} <= {shares.get(item.nodeid)}
    listed_here = {item.nodeid for item in items} & set(seconds)
    assert listed_here <= set(shares)  # every listed test collected here is in exactly one share
    load = [sum(seconds.get(n, 0.0) for n, k in shares.items() if k == share) for share in (1, 2)]
    if sum(load):  # greedy, longest first: the shares differ by at most the longest test
        assert abs(load[0] - load[1]) <= max(seconds[n] for n in listed_here)
