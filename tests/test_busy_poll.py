"""common.udp.BusyPoll: lockstep waits poll their socket first, and stop polling while it catches nothing."""

import socket

import pytest

from common.udp import BusyPoll, UdpEndpoint


@pytest.fixture(autouse=True)
def _two_cpus(request, monkeypatch):
    """Polling needs two CPUs (a process on one never polls): the policy tests assume them."""
    if request.node.name != "test_a_process_on_one_cpu_never_polls":
        monkeypatch.setattr("common.udp.usable_cpus", lambda: 2)


def test_three_empty_polls_in_a_row_pause_polling_for_a_doubling_number_of_waits():
    p = BusyPoll(0.001)
    assert p.window() == 0.001
    p.missed()
    p.missed()
    assert p.window() == 0.001          # two misses: still polling
    p.missed()                          # the third in a row: a pause of FIRST_PAUSE waits
    assert [p.window() for _ in range(BusyPoll.FIRST_PAUSE)] == [0.0] * BusyPoll.FIRST_PAUSE
    assert p.window() == 0.001
    for _ in range(3):
        p.missed()
    assert sum(p.window() == 0.0 for _ in range(4 * BusyPoll.FIRST_PAUSE)) == 2 * BusyPoll.FIRST_PAUSE
    assert p.summary() == {"max_us": 1000.0, "caught": 0, "missed": 6, "pauses": 2, "held": 0}


def test_a_catch_resets_the_run_of_misses_and_the_pause_length():
    p = BusyPoll(0.002)
    for _ in range(3):
        p.missed()                      # pause 1: FIRST_PAUSE waits, the next one twice as long
    for _ in range(BusyPoll.FIRST_PAUSE):
        p.window()
    p.missed()
    p.missed()
    p.caught()                          # breaks the run: two more misses do not pause
    p.missed()
    p.missed()
    assert p.window() == 0.002
    p.missed()                          # a new run of three: the pause is FIRST_PAUSE again, not doubled
    assert sum(p.window() == 0.0 for _ in range(4 * BusyPoll.FIRST_PAUSE)) == BusyPoll.FIRST_PAUSE


def test_pauses_are_capped():
    p = BusyPoll(0.001)
    for _ in range(20):
        for _ in range(3):
            p.missed()
        while p.window() == 0.0:
            pass
    assert p._pause == BusyPoll.MAX_PAUSE


def test_a_held_poll_sleeps_at_once_and_keeps_its_pause_schedule():
    """The vessel computer holds its polls while its planner worker has a request: each wait
    sleeps at once (counted), and a pause under way resumes where it was once released."""
    p = BusyPoll(0.001)
    for _ in range(3):
        p.missed()                      # a pause of FIRST_PAUSE waits begins
    p.window()
    p.hold(True)
    assert [p.window() for _ in range(50)] == [0.0] * 50
    p.hold(False)
    assert sum(p.window() == 0.0 for _ in range(BusyPoll.FIRST_PAUSE)) == BusyPoll.FIRST_PAUSE - 1
    assert p.window() == 0.001
    assert p.summary() == {"max_us": 1000.0, "caught": 0, "missed": 3, "pauses": 1, "held": 50}


def test_negative_window_is_refused():
    with pytest.raises(ValueError):
        BusyPoll(-1e-3)


def test_recv_polls_and_catches_a_datagram_that_arrives_after_its_first_read():
    ep = UdpEndpoint("127.0.0.1:0")
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    class SendsWhenAsked(BusyPoll):
        def window(self) -> float:
            # recv asks for the window after its first read found nothing; a loopback datagram is
            # queued when sendto returns, so the poll that follows is the path that reads it
            tx.sendto(b"frame", ep.address)
            return super().window()

    try:
        poll = SendsWhenAsked(2.0)
        assert ep.recv(timeout=10.0, poll=poll) == b"frame"
        assert (poll.hits, poll.misses) == (1, 0)
        tx.sendto(b"queued", ep.address)
        assert ep.recv(timeout=10.0, poll=BusyPoll(2.0)) == b"queued"   # already there: no poll at all
    finally:
        tx.close()
        ep.close()


def test_recv_with_a_poll_keeps_its_timeout_and_counts_the_miss():
    ep = UdpEndpoint("127.0.0.1:0")
    try:
        poll = BusyPoll(0.5)
        assert ep.recv(timeout=0.01, poll=poll) is None   # the poll is cut to the timeout
        assert (poll.hits, poll.misses) == (0, 1)
        assert ep.recv(timeout=0.0, poll=poll) is None    # no wait, no poll
        assert (poll.hits, poll.misses) == (0, 1)
    finally:
        ep.close()


def test_a_process_on_one_cpu_never_polls(monkeypatch):
    import common.udp as udp

    monkeypatch.setattr(udp, "usable_cpus", lambda: 1)
    p = BusyPoll(0.001)
    assert p.window() == 0.0 and p.summary()["max_us"] == 0.0
    monkeypatch.setattr(udp, "usable_cpus", lambda: 2)
    assert BusyPoll(0.001).window() == 0.001
