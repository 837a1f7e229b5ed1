"""Progress off a terminal (issue 40: a 27-minute fit printed nothing to its log): a line every 5% of the
work after the first 10 s, at most one per 10 s; a short command prints nothing."""
import io
import subprocess
import sys

from snapshot3d.progress import LogLines, progress


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_lines_every_five_percent_after_the_quiet_start():
    clock, out = Clock(), io.StringIO()
    bar = LogLines(1000, "fit", stream=out, clock=clock)
    for _ in range(1000):
        clock.t += 0.125        # 125 s of work in all
        bar.update(1)
        bar.set_postfix_str("psnr 30.1")
    lines = out.getvalue().splitlines()
    assert lines[0] == "fit: 8% (80/1000 step), 0m10s, about 1m55s left, psnr 30.1"
    assert lines[1].startswith("fit: 16% (160/1000 step), 0m20s")
    assert lines[-1] == "fit: 100% (1000/1000 step), 2m05s, psnr 30.1"
    assert len(lines) == 13     # one per 10 s (12), and the last


def test_a_short_job_prints_nothing():
    clock, out = Clock(), io.StringIO()
    with LogLines(20, "decode", unit="view", stream=out, clock=clock) as bar:
        for _ in range(20):
            clock.t += 0.2
            bar.update(1)
    assert out.getvalue() == ""


def test_off_a_terminal_progress_writes_log_lines_not_a_bar():
    code = "from snapshot3d.progress import progress, LogLines; import sys; print(type(progress(5, 'x')).__name__)"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env={"PATH": ""})
    assert proc.stdout.strip() == "LogLines" and proc.stderr == ""
    assert type(progress(5, "x")).__name__ in ("LogLines", "tqdm")


def test_n_set_directly_then_refresh_as_the_fit_does():
    """train/field/commands.py sets `bar.n = step`, `set_postfix_str(..., refresh=False)`, `refresh()` (tqdm's API)."""
    clock, out = Clock(), io.StringIO()
    bar = LogLines(100, "fit", stream=out, clock=clock)
    for step in range(25, 101, 25):
        clock.t += 20.0
        bar.n = step
        bar.set_postfix_str(f"psnr {step / 4:.2f} dB", refresh=False)
        bar.refresh()
    assert out.getvalue().splitlines() == [
        "fit: 25% (25/100 step), 0m20s, about 1m00s left, psnr 6.25 dB",
        "fit: 50% (50/100 step), 0m40s, about 0m40s left, psnr 12.50 dB",
        "fit: 75% (75/100 step), 1m00s, about 0m20s left, psnr 18.75 dB",
        "fit: 100% (100/100 step), 1m20s, psnr 25.00 dB"]
