"""The wake-up penalty probe runs and prints one row per piece of work."""

from benchmarks import wake_penalty


def test_prints_hot_and_after_sleep_times_for_every_piece_of_work(capsys):
    assert wake_penalty.main(["--n", "3", "--gap-ms", "1"]) == 0
    rows = capsys.readouterr().out.splitlines()[2:]
    assert len(rows) == 4
    for row in rows:
        hot, cold, spun = (float(v) for v in row.split()[-4:-1])
        assert hot > 0 and cold > 0 and spun > 0, row
