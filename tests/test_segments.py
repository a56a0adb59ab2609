import numpy as np
import pytest

from aerosid.preprocess.segments import split_segments

T = np.round(np.arange(0, 9001) * 0.01, 10)


def test_split_at_the_sync_gap_excludes_the_gap_samples():
    segs = split_segments(T, [(40.0, 42.0)])
    assert [s.segment_id for s in segs] == ["seg00", "seg01"]
    assert T[segs[0].stop - 1] < 40.0 and T[segs[1].start] > 42.0
    assert segs[1].stop == len(T)


def test_user_windows_are_half_open_and_do_not_share_samples():
    segs = split_segments(T, [], [(0, 30), (30, 90)])
    assert segs[0].stop == segs[1].start
    assert sum(s.n_rows for s in segs) == len(T)


def test_short_pieces_are_dropped_and_empty_windows_rejected():
    assert [s.t_start_s for s in split_segments(T, [(3.0, 4.0)], min_duration_s=5.0)] == [pytest.approx(4.01)]
    with pytest.raises(ValueError, match="empty"):
        split_segments(T, [], [(10, 10)])
    assert split_segments(np.array([]), []) == []
