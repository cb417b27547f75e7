"""The drivers' exception tree: one root, time-outs also TimeoutError, argument errors also ValueError."""

from __future__ import annotations

import inspect

from drivers import errors


def test_every_driver_exception_descends_from_driver_error() -> None:
    classes = [c for _, c in inspect.getmembers(errors, inspect.isclass) if c.__module__ == errors.__name__]
    assert len(classes) >= 14 and all(issubclass(c, errors.DriverError) for c in classes)


def test_tree_shape() -> None:
    e = errors
    assert issubclass(e.DeviceTimeout, TimeoutError) and issubclass(e.CanTimeout, TimeoutError)
    assert issubclass(e.CanTimeout, e.DeviceTimeout) and issubclass(e.CanTimeout, e.CanDriverError)
    assert issubclass(e.DriverConfigError, ValueError) and issubclass(e.CanConfigError, e.DriverConfigError)
    for frame_error in (e.CobsError, e.MalformedFrame, e.CrcMismatch):
        assert issubclass(frame_error, e.FrameError)
    for can_error in (e.CanBusError, e.CanLogError, e.CanConfigError):
        assert issubclass(can_error, e.CanDriverError)
