"""``rimd crop`` (docs/recording.md): a window of a recording as a new rosbag2 recording, read back by rosbags and mcap.

The source is an MCAP file written from the physics core's output by ``mcap_ros2``'s writer
(:func:`harness.rig_mcap.write_rig_mcap`), not by the code under test; the expected window is computed here
from the source as ``mcap`` reads it (log times within [first + start, first + end], both included).
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from harness.bags import read_with_mcap_ros2, read_with_rosbags
from harness.rig_mcap import write_rig_mcap
from rimd_sim import cli


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    """Three seconds of the rig (100 blocks/s per channel, impacts, motor states) in one MCAP file."""
    return write_rig_mcap(tmp_path_factory.mktemp("crop") / "rec.mcap", seconds=3.0).path


def _window(messages, start_s: float, end_s: float, topics=None):
    first = min(t for _, _, t, _ in messages)
    lo, hi = first + round(start_s * 1e9), first + round(end_s * 1e9)
    return [(topic, raw, t) for topic, raw, t, _ in messages
            if lo <= t <= hi and (topics is None or topic in topics)]


def test_crop_writes_exactly_the_window_as_a_rosbag2_recording(source, tmp_path, capsys):
    out = tmp_path / "window"
    assert cli.main(["crop", str(source), "--start", "1.0", "--end", "2.0", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    original = read_with_mcap_ros2(source)
    expected = _window(original, 1.0, 2.0)
    assert 0 < len(expected) < len(original)

    counts, by_rosbags = read_with_rosbags(out)   # the directory, through its metadata.yaml
    assert [(topic, raw, t) for topic, raw, t, _ in by_rosbags] == expected   # same bytes, same times, same order
    files = sorted(out.glob("*.mcap"))
    assert len(files) == 1 and files[0].name.startswith("rimd_")
    assert [(topic, raw, t) for topic, raw, t, _ in read_with_mcap_ros2(files[0])] == expected
    per_topic = {topic: sum(1 for m in expected if m[0] == topic) for topic in {m[0] for m in original}}
    assert counts == per_topic
    # rosbag2's metadata.yaml and the MCAP summary agree with what is in the file.
    info = yaml.safe_load((out / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["message_count"] == len(expected) and info["storage_identifier"] == "mcap"
    assert info["starting_time"]["nanoseconds_since_epoch"] == expected[0][2]
    assert info["duration"]["nanoseconds"] == max(t for *_, t in expected) - expected[0][2]
    from mcap.reader import make_reader

    with files[0].open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert reader.get_header().profile == "ros2"
        assert summary.statistics.message_count == len(expected)
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        assert "rimd_crop" in {m.name for m in reader.iter_metadata()}
    assert f"{len(expected)} messages" in printed


def test_crop_keeps_the_topics_asked_and_goes_to_the_end_by_default(source, tmp_path):
    out = tmp_path / "force"
    assert cli.main(["crop", str(source), "--start", "2.5", "--topics", "/rig/impact/force", "/rig/impact/events",
                     "--out", str(out)]) == 0
    original = read_with_mcap_ros2(source)
    last = max(t for *_, t, _ in original) - min(t for *_, t, _ in original)
    expected = _window(original, 2.5, last / 1e9, topics={"/rig/impact/force", "/rig/impact/events"})
    _, by_rosbags = read_with_rosbags(out)
    assert [(topic, raw, t) for topic, raw, t, _ in by_rosbags] == expected
    assert sum(1 for m in expected if m[0] == "/rig/impact/force") >= 40   # 100 blocks/s over the last 0.5 s


@pytest.mark.parametrize(("args", "message"), [
    (["--start", "2", "--end", "1"], "rimd crop: --end 1 s refused: must not be before --start 2 s"),
    (["--start", "5"], "rimd crop: --start 5 s refused: outside the recording, which spans 0 to {span} s"),
    (["--end", "9"], "rimd crop: --end 9 s refused: outside the recording, which spans 0 to {span} s"),
    (["--topics", "/rig/nope"], "rimd crop: --topics /rig/nope refused: not in "),
])
def test_bad_windows_are_refused_in_one_line(source, tmp_path, capsys, args, message):
    out = tmp_path / "bad"
    assert cli.main(["crop", str(source), *args, "--out", str(out)]) == 1
    err = capsys.readouterr().err
    times = [t for *_, t, _ in read_with_mcap_ros2(source)]
    assert err.startswith(message.format(span=f"{(max(times) - min(times)) / 1e9:.9g}")), err
    assert err.count("\n") == 1
    assert not out.exists() or not any(out.iterdir()), "nothing written"


def test_a_negative_start_is_a_usage_error(source, tmp_path, capsys):
    with pytest.raises(SystemExit) as usage:
        cli.main(["crop", str(source), "--start", "-1", "--out", str(tmp_path / "bad")])
    assert usage.value.code == 2 and "--start -1 refused: must be >= 0 s" in capsys.readouterr().err
