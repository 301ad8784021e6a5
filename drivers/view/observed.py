"""`ObservedTracker`: a `drivers.client.Tracker` that reports every sample it hands out and every target it shows.

The view lets `eyehil.drivers.calibration.calibrate` drive the device unchanged and still shows the samples and
the targets of the calibration live: `on_sample(sample)` runs for each sample `read_sample` returns,
`on_target(target_id, x_mm, y_mm)` for each STIMULUS (STIMULUS mm: top-left origin, x right, y down).
"""

from __future__ import annotations

from collections.abc import Callable

from eyehil.drivers.client import Tracker
from eyehil.drivers.links import open_link
from eyehil.drivers.wire import Sample


class ObservedTracker(Tracker):
    """See the module docstring."""

    on_sample: Callable[[Sample], None] | None = None
    on_target: Callable[[int, float, float], None] | None = None

    def read_sample(self, timeout: float | None = None) -> Sample:
        sample = super().read_sample(timeout)
        if self.on_sample is not None:
            self.on_sample(sample)
        return sample

    def stimulus(self, target_id: int, x_mm: float, y_mm: float, visible: bool = True) -> int:
        onset = super().stimulus(target_id, x_mm, y_mm, visible)
        if self.on_target is not None and visible:
            self.on_target(target_id, x_mm, y_mm)
        return onset


def open_observed(url: str, **kwargs) -> ObservedTracker:
    """Open `url` (any scheme of `eyehil.drivers.links`) and handshake, like `eyehil.drivers.client.open_tracker`."""
    link = open_link(url, timeout=0.0)
    try:
        return ObservedTracker(link, url=url, **kwargs)
    except BaseException:
        link.close()
        raise
