"""list_runs: newest first, says when it was cut (total, more, the repr), continues with page_token, orders by
any field, filters by name; bad order_by and a token reused with other filters name the field."""
import pytest

import valvebench

N = 7


def spec(name):
    return {"name": name, "controller": {"open_loop_pwm": {"segments": [{"frequency_Hz": 0, "duty": 1}]}},
            "conditions": {"supply_V": 24}, "duration_s": 0.005, "recording": {"rate_Hz": 10000}}


@pytest.fixture(scope="module")
def listed(local_client):
    ids = []
    for k in range(N):
        batch = local_client.submit(spec("py-list-%d" % k))
        batch.wait()
        ids.extend(batch.run_ids)
    return ids


def test_newest_first_and_says_when_cut(local_client, listed):
    runs = local_client.list_runs(limit=3)
    assert isinstance(runs, valvebench.RunList) and isinstance(runs, list)
    assert [r.id for r in runs] == sorted(listed, reverse=True)[:3]
    assert runs.total == N and runs.more == N - 3 and runs.truncated
    assert runs.next_page_token
    assert "3 of %d runs (submitted desc); %d more" % (N, N - 3) in repr(runs)
    rest = local_client.list_runs(limit=None)
    assert [r.id for r in rest] == sorted(listed, reverse=True)
    assert rest.total == N and rest.more == 0 and not rest.truncated and rest.next_page_token == ""
    assert "more" not in repr(rest)


def test_page_token_continues_the_same_listing(local_client, listed):
    first = local_client.list_runs(limit=3, order_by="id")
    second = local_client.list_runs(limit=3, order_by="id", page_token=first.next_page_token)
    assert [r.id for r in first] + [r.id for r in second] == sorted(listed)[:6]
    with pytest.raises(valvebench.InvalidArgument, match="page_token"):
        local_client.list_runs(limit=3, order_by="id desc", page_token=first.next_page_token)
    with pytest.raises(valvebench.InvalidArgument, match="page_token"):
        local_client.list_runs(limit=3, order_by="id", name="list", page_token=first.next_page_token)


def test_order_by_and_name_filter(local_client, listed):
    by_name = local_client.list_runs(order_by="name desc", limit=None)
    assert [r.name for r in by_name] == sorted((r.name for r in by_name), reverse=True)
    one = local_client.list_runs(name="LIST-4")
    assert [r.name for r in one] == ["py-list-4"] and one.total == 1
    with pytest.raises(valvebench.InvalidArgument, match="order_by.*id, submitted, started"):
        local_client.list_runs(order_by="newest")
    with pytest.raises(valvebench.InvalidArgument, match="limit"):
        local_client.list_runs(limit=0)
