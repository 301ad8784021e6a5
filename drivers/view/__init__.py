"""The live web view: a host (it sees only the wire) that serves a page of the tracker's camera, features, gaze
and health (docs/view.md). Optional extra ``view`` (aiohttp).

- `cli`: ``eyehil view URL`` and the options ``eyehil emulate --view`` shares
- `server`: the aiohttp server (page, WebSocket, stats) on its own thread
- `session`: the device thread: connect, stream, commands, calibration, reconnect, publish
- `live`: what the page is shown of the stream: chart rows, records per exposure, gaze, health (no I/O)
- `observed`: a `Tracker` that reports the samples and targets a calibration uses
- `hub`: fan-out to the pages with bounded queues
- `payload`: the JSON and binary messages of the page (pure)
- `scripts`: host-side gaze scripts (fixations, pursuit, grid) sent as STIMULUS (pure)
- `stats`: rate, latency percentiles (pure)
- `overlay`: the eye panel drawn with OpenCV (pure)
- `video`: ``--record-video`` (MP4 or animated PNG)
- `static/`: index.html, view.js, view.css (the page; no CDN)
"""
