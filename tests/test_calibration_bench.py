"""The calibration benchmark's arithmetic: shares of frames inside the belief's 95 % spread."""

from benchmarks.calibration import calibration


def test_calibration_counts_frames_inside_the_radius_and_heading_after_the_frame_offset() -> None:
    # room frame = map frame + (50, 50); the first row fixes that offset
    rows = [
        (50.0, 50.0, 0.0, 0.0, 0.0, 0.0, 2.0, 1.0),  # exact
        (60.0, 50.0, 10.0, 7.0, 0.0, 0.0, 5.0, 20.0),  # 3 cm off (inside 5), 10 deg (inside 20)
        (60.0, 50.0, 359.0, 0.0, 0.0, 2.0, 4.0, 2.0),  # 10 cm off (outside 4), 3 deg across 0
    ]
    c = calibration(rows)
    assert c is not None
    assert c["frames"] == 3
    assert c["xy95"] == 2 / 3
    assert c["heading95"] == 2 / 3
    assert c["worst_excess_cm"] == 6.0


def test_calibration_of_no_frames_is_none() -> None:
    assert calibration([]) is None
