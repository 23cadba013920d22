"""The performance figures' own helpers: the streaming copy's size and the README's table."""

import pytest

from rts_scenario import perf


def _sysfs(root, sizes):
    for i, size in enumerate(sizes):
        (root / f"index{i}").mkdir()
        (root / f"index{i}" / "size").write_text(f"{size}\n")
    return root


def test_last_level_cache_is_the_largest_cache_sysfs_lists(tmp_path):
    root = _sysfs(tmp_path, ["48K", "32K", "1024K", "32768K"])
    assert perf.last_level_cache_bytes(root) == 32 * 1024 * 1024
    other = tmp_path / "other"
    other.mkdir()
    assert perf.last_level_cache_bytes(_sysfs(other, ["2M", "1G"])) == 1 << 30


def test_last_level_cache_without_sysfs_is_the_default(tmp_path):
    assert perf.last_level_cache_bytes(tmp_path / "none") == 32 << 20
    root = _sysfs(tmp_path, ["unknown", "12X"])  # unreadable sizes are skipped
    assert perf.last_level_cache_bytes(root) == 32 << 20


@pytest.mark.parametrize(("cache", "expected"), [(32 << 20, 128 << 20), (1 << 20, 64 << 20),
                                                 (256 << 20, 1 << 30)])
def test_streaming_copy_is_four_times_the_cache_and_at_least_64_mib(cache, expected):
    assert perf.streaming_copy_bytes(cache) == expected


def test_markdown_table_groups_thousands_and_marks_goals_not_met():
    figures = [perf.Figure("CAN", 125975.4, "messages/s", "virtual bus", 39731.0, 3.1706,
                           ">= 100,000 messages/s", True),
               perf.Figure("traffic", 2.4417, "GB/s", "streaming copy", 25.13, 0.09716,
                           ">= 0.10x the streaming copy", False)]
    lines = perf.format_markdown(figures).splitlines()
    assert lines[0] == "| figure | measured | comparison (same run) | ratio | goal | |"
    assert lines[2] == ("| CAN | 125,975 messages/s | virtual bus: 39,731 messages/s | 3.17× | "
                        "≥ 100,000 messages/s | met |")
    assert lines[3] == ("| traffic | 2.44 GB/s | streaming copy: 25.1 GB/s | 0.0972× | "
                        "≥ 0.10x the streaming copy | **not met** |")


def test_readme_performance_table_is_the_markdown_format():
    """The README's table is `bench --markdown`'s: same header, one row per figure."""
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    header = perf.format_markdown([]).splitlines()[0]
    assert header in readme
    start = readme.index(header)
    rows = readme[start:].split("\n\n")[0].splitlines()[2:]
    # CAN 1, solver 3 x 2, radar 2, quantization 1, scale 2, start-up 3.
    assert len(rows) == 15 and all(r.count("|") == 7 for r in rows)
    names = [r.split("|")[1].strip() for r in rows]
    assert "start-up of a cut-in run (the command's)" in names
    assert any(n.startswith("adc frame, awr1843boost, 8 targets (20 in a row)") for n in names)
