"""Progress display: plain lines when not on a terminal, with step, time, dt, vrms and an ETA."""

import io

from convection.run.progress import Progress, is_terminal


def test_not_a_terminal_gives_lines():
    stream = io.StringIO()
    assert not is_terminal(stream)
    progress = Progress(1.0, mode="auto", every=2, stream=stream)
    assert progress.mode == "lines"
    for step, t in enumerate((0.0, 0.25, 0.5)):
        progress.update(step, t, 0.25, 10.0 + step)
    progress.close()
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2  # steps 0 and 2
    assert lines[1].split()[:2] == ["step", "2"] and "vrms=12" in lines[1] and "ETA" in lines[1]


def test_disabled_on_other_ranks_writes_nothing():
    stream = io.StringIO()
    progress = Progress(1.0, mode="lines", enabled=False, stream=stream)
    progress.update(0, 0.0, 0.1, 1.0, force=True)
    progress.message("hello")
    assert stream.getvalue() == ""
