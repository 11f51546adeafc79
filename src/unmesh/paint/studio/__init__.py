"""The painting studio in the browser: ``unmesh paint MODEL`` (issue 19, thesis chapter 5).

A local aiohttp server (:mod:`~unmesh.paint.studio.server`, :func:`run_studio`) streams the
painting session's renders over a WebSocket to a page of plain JavaScript modules served from
the package (``static/``, no build step, works offline). The page sends pen samples (pressure,
tilt, coalesced events, dab spacing by distance), view changes and tool commands; the server
ray-casts the pen onto the surface, paints through :class:`unmesh.paint.Session`, and returns
the changed tiles. See ``docs/paint_studio.md``.

Modules: :mod:`~unmesh.paint.studio.security` (token, origin, static files, output paths),
:mod:`~unmesh.paint.studio.protocol` (message validation), :mod:`~unmesh.paint.studio.view`
(orbit view to camera), :mod:`~unmesh.paint.studio.frames` (tile encoding),
:mod:`~unmesh.paint.studio.workspace` (session, palette, files, autosave),
:mod:`~unmesh.paint.studio.server` (HTTP/WebSocket).
"""
