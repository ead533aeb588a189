"""The ROS domains a graph or run without one picks from (`processes.auto_domains`).

Test workers side by side on one loopback each get their own part of 1..100 through
``$SSA_FUSION_DOMAINS`` (test/conftest.py); a graph's fresh domain and a run's free-domain
search both stay inside it.
"""

import random

import pytest

from ssa_fusion.ros import domains
from ssa_fusion.ros.processes import DOMAINS_ENV, auto_domains, fresh_domain_id


def test_without_the_variable_every_domain_below_the_ephemeral_ports(monkeypatch):
    monkeypatch.delenv(DOMAINS_ENV, raising=False)
    assert auto_domains() == range(1, 102)


def test_fresh_domains_stay_in_the_part_given(monkeypatch):
    monkeypatch.setenv(DOMAINS_ENV, "51-60")
    picked = {fresh_domain_id() for _ in range(40)}
    assert picked <= set(range(51, 61))
    assert len(picked) == 10  # consecutive graphs of one process take different domains


@pytest.mark.parametrize("raw", ["0-10", "20-10", "5", "a-b", "90-102", "-3"])
def test_a_malformed_part_is_refused_naming_the_variable(monkeypatch, raw):
    monkeypatch.setenv(DOMAINS_ENV, raw)
    with pytest.raises(ValueError, match=f"{DOMAINS_ENV}=.*first-last within 1-101"):
        auto_domains()


def test_a_runs_free_domain_search_stays_in_the_part_given(monkeypatch, tmp_path):
    tried: list[int] = []

    class Busy:
        """A graph whose domain always holds another run's node."""

        def __init__(self, _workdir, domain, *_args):
            tried.append(domain)

        def others(self, _look_s):
            return ["/ssa_other/filter"]

        def close(self):
            pass

    monkeypatch.setattr(domains, "Graph", Busy)
    monkeypatch.setenv(DOMAINS_ENV, "31-35")
    with pytest.raises(domains.DomainInUseError, match=r"in 5 tries of 31\.\.35"):
        domains.open_graph(tmp_path, None, "run1", rng=random.Random(4))
    assert sorted(tried) == [31, 32, 33, 34, 35]
