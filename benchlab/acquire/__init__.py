"""Acquisition: streams from the drivers into the run file (raw groups, events, the /aligned grid)."""

from benchlab.acquire.writer import AlignedBuilder, AlignedSource, Layout, RunWriter, StreamSpec

__all__ = ["AlignedBuilder", "AlignedSource", "Layout", "RunWriter", "StreamSpec"]
