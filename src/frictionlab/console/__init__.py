"""The operator console of the real-time controller (Sec. 7.1): a page in a browser.

``frictionlab run`` hands its :class:`~frictionlab.realtime.RealtimeController`
to :func:`serve`, which serves the console at http://127.0.0.1:8000.  The
page (``static/``; no build step, the plot library uPlot vendored under
``static/vendor``) has the thesis's Start/Stop, live plot with per-signal
toggles, Save Data with the ``out>`` file-name prompt, State Feedback and
Kalman Filter panels with Fast/Slow, Compensation with Friction Type and
Friction Model, Exit, plus a push button for simulated rigs and a status
line with timing statistics and the running limit-cycle figures.

Modules: :mod:`.app` (the application), :mod:`.routes` (one ``APIRouter``
module per concept: page and status, run, parameters, experiments,
recordings, the WebSocket), :mod:`.hub` (the plot stream's fan-out),
:mod:`.state` (what the routes share), :mod:`.errors` (error answers),
:mod:`.models` (request validation), :mod:`.security` (token, origin, size
and time limits), :mod:`.stream` (reading samples off the tick thread),
:mod:`.server` (uvicorn).
User's guide: ``docs/console.md``.
"""

from .app import create_app
from .server import console_url, serve

__all__ = ["console_url", "create_app", "serve"]
