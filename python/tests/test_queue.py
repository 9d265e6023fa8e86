"""queue(): the server's GetQueue view (what benchctl queue prints): every run submitted and not yet ended is
in it once, running runs at position 0, queued runs at positions 1, 2, ... in claim order with ETAs that do not
decrease along the queue; an empty queue once they have ended."""
import valvebench

N = 12


def spec(name):
    return {"name": name, "controller": {"open_loop_pwm": {"segments": [{"frequency_Hz": 0, "duty": 1}]}},
            "conditions": {"supply_V": 24}, "duration_s": 0.05, "recording": {"rate_Hz": 10000}}


def test_queue_positions_and_etas(local_client):
    batches = [local_client.submit(spec("py-queue-%d" % k)) for k in range(N)]
    ids = {i for b in batches for i in b.run_ids}
    q = local_client.queue()
    assert isinstance(q, valvebench.Queue)
    assert q.live_benches >= 1 and q.benches
    listed = [r.id for r, _, _ in q.running + q.queued]
    assert len(listed) == len(set(listed))
    mine = [i for i in listed if i in ids]
    # A run of ours that is not in the view has ended already: the server says so.
    for i in ids - set(mine):
        assert local_client.get_run(i).ended
    assert all(pos == 0 for _, pos, _ in q.running)
    assert [pos for _, pos, _ in q.queued] == list(range(1, len(q.queued) + 1))
    etas = [eta for _, _, eta in q.queued if eta is not None]
    assert etas == sorted(etas)
    df = q.to_dataframe()
    assert list(df.index) == listed and set(df.columns) >= {"position", "eta_s", "status"}
    assert "%d queued" % len(q.queued) in repr(q)
    for b in batches:
        b.wait()
    after = local_client.queue()
    assert not [r for r, _, _ in after.running + after.queued if r.id in ids]
