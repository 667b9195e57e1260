"""The algorithm registry: the protocol roles the report reads instead of algorithm names."""

from adarl.algos import registry


def test_protocol_roles_come_from_the_registry():
    roles = {
        name: {role: registry.role(name, role) for role in ("adapts_rank", "rank_sweep", "best_of")}
        for name in registry.ALGOS
    }
    assert [n for n, r in roles.items() if r["adapts_rank"]] == ["adarl"]
    assert [n for n, r in roles.items() if r["rank_sweep"]] == ["sac-fixed-rank"]
    assert {n: r["best_of"] for n, r in roles.items() if r["best_of"]} == {
        "sac-parseval": "parseval_coef"
    }
    # a run of an algorithm this version does not know plays no role
    assert registry.role("td3", "adapts_rank") is False and registry.role("td3", "best_of") is None
    assert registry.REFERENCE in registry.ALGOS
    assert set(registry.REPORT_ORDER) <= set(registry.ALGOS)
