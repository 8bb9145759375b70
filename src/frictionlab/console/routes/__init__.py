"""The console's HTTP API, one FastAPI ``APIRouter`` module per concept.

Each module's ``router(ctx)`` builds its routes over the shared
:class:`~frictionlab.console.state.Context`:

* :mod:`.page`: the page, its static files, ``/api/status`` and ``/api/schema``;
* :mod:`.run`: Start, Swing up, Stop, Exit;
* :mod:`.params`: the State Feedback / Kalman Filter and Compensation panels, the push;
* :mod:`.experiments`: the Experiments panel;
* :mod:`.recordings`: Save Data, the ``out>`` prompt and downloads;
* :mod:`.ws`: the plot and status stream (``/ws``).
"""

from . import experiments, page, params, recordings, run, ws

#: The router modules, in the order :func:`frictionlab.console.create_app` includes them.
MODULES = (page, run, params, experiments, recordings, ws)

__all__ = ["MODULES"]
