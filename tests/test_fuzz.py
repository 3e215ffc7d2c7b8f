"""Fuzzing the decode path: any frame, any ID, DLC and payload, never an exception, always accounted."""
import can
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from canest.codec.decode import InputDecoder
from canest.pipeline import Pipeline

MAPPED = [0xB4, 0xB6, 0xC2, 0x130, 0x140, 0x1D0, 0x1D2]

frames = st.builds(
    lambda frame_id, mapped, extended, data, remote, error, fd, t: can.Message(
        arbitration_id=(mapped if frame_id is None else frame_id), is_extended_id=extended, data=data,
        is_remote_frame=remote, is_error_frame=error, is_fd=fd, timestamp=t, check=False),
    st.one_of(st.none(), st.integers(0, 0x1FFFFFFF)), st.sampled_from(MAPPED), st.booleans(),
    st.binary(min_size=0, max_size=64), st.booleans(), st.booleans(), st.booleans(),
    st.floats(0, 1e9, allow_nan=False))


@settings(max_examples=3000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(frames, min_size=1, max_size=30))
def test_any_frames_are_decoded_or_counted_never_raise(config, batch):
    decoder = InputDecoder(config)
    for frame in batch:
        decoder.decode(frame)
    counts = decoder.counts
    rejected = sum(v for k, v in counts.items() if k.startswith("rejected_"))
    assert counts["frames"] == len(batch) == counts["decoded"] + counts["ignored_id"] + rejected


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(frames, min_size=1, max_size=60))
def test_the_pipeline_survives_any_frames(config, batch):
    pipeline = Pipeline(config)
    for frame in sorted(batch, key=lambda f: f.timestamp):
        for estimate in pipeline.feed(frame):
            pipeline.encoder.encode(estimate)
