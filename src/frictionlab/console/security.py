"""Access control of the operator console (an ASGI middleware) and bind-address checks.

The console moves a motor, so it is closed by default:

* It binds to 127.0.0.1.  Binding any other address needs a token
  (:func:`check_bind`); a console without a token refuses to start there.
* With a token, every HTTP request and every WebSocket must carry it:
  ``Authorization: Bearer TOKEN``, the query parameter ``?token=TOKEN``
  (for the first page load and the WebSocket URL), or the cookie the page
  load sets (``HttpOnly; SameSite=Strict``).  Otherwise HTTP gets 401, and
  so does a WebSocket handshake (closed with code 1008, policy violation,
  where the server cannot answer a handshake with an HTTP status).
* A request whose ``Origin`` is not the console's own address is refused
  (403, also for a WebSocket handshake): no CORS, and no other site's page can
  drive the console through the operator's browser.  On a loopback bind the
  ``Host`` header must name a loopback address (DNS rebinding).
* ``POST`` bodies must be ``application/json`` (415).  Any request's body (a
  ``GET``'s too) must be at most ``max_body`` bytes (413), counted as they
  arrive, and complete within ``body_timeout`` seconds of the request head
  (408, and the connection is closed): a client that sends a head and then
  stalls, or trickles its body, holds no connection.
* A refused request's connection is closed after the answer
  (``Connection: close``), so a client without the token holds no
  connection; connections that send no complete request are closed by the
  server (:mod:`.server`).
"""

from __future__ import annotations

import asyncio
import hmac
import ipaddress
import json
import os
from http.cookies import SimpleCookie
from urllib.parse import parse_qs, urlsplit

from ..model.params import ParamError

__all__ = [
    "BODY_TIMEOUT",
    "COOKIE",
    "MAX_BODY",
    "MIN_TOKEN_LENGTH",
    "TOKEN_ENV",
    "Guard",
    "check_bind",
    "is_loopback",
    "resolve_token",
]

#: Environment variable read when no token is given.
TOKEN_ENV = "FRICTIONLAB_TOKEN"
#: Cookie set by an authorised page load.
COOKIE = "frictionlab_token"
#: Largest request body accepted (bytes).
MAX_BODY = 64 * 1024
#: Seconds a request body has to arrive in full after its head (as the head has, in
#: :data:`frictionlab.console.server.HEAD_TIMEOUT`).
BODY_TIMEOUT = 3.0
MIN_TOKEN_LENGTH = 8
_LOOPBACK_NAMES = ("localhost",)


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``."""
    host = host.strip("[]")
    if host.lower() in _LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def resolve_token(token: str | None, environ=None) -> str | None:
    """The token to use: ``token`` if given, else ``$FRICTIONLAB_TOKEN``, else None.

    Raises
    ------
    ParamError
        (field ``token``) If the token is shorter than :data:`MIN_TOKEN_LENGTH`
        characters.
    """
    environ = os.environ if environ is None else environ
    if token is None or token == "":
        token = environ.get(TOKEN_ENV) or None
    if token is not None and len(token) < MIN_TOKEN_LENGTH:
        raise ParamError("token", f"{len(token)} characters", f">= {MIN_TOKEN_LENGTH} characters",
                         f"the console token must have at least {MIN_TOKEN_LENGTH} characters")
    return token


def check_bind(host: str, token: str | None) -> None:
    """Refuse to serve on a non-loopback address without a token.

    Raises
    ------
    ParamError
        (field ``token``) Naming the address and the token's environment variable.
    """
    if not is_loopback(host) and not token:
        raise ParamError("token", None, f"a token when {host} is not a loopback address",
                         f"binding the console to {host} (not a loopback address) needs a token: "
                         f"give one or set {TOKEN_ENV}")


def _headers(scope) -> dict[str, str]:
    out: dict[str, str] = {}
    for k, v in scope.get("headers", ()):
        key = k.decode("latin-1").lower()
        val = v.decode("latin-1")
        out[key] = f"{out[key]}; {val}" if key == "cookie" and key in out else val
    return out


def _host_only(hostport: str) -> str:
    if hostport.startswith("["):
        return hostport[1:].split("]", 1)[0]
    return hostport.rsplit(":", 1)[0] if hostport.count(":") == 1 else hostport


class Guard:
    """ASGI middleware: token, origin, host, content type and body size checks.

    Parameters
    ----------
    app
        The wrapped ASGI application.
    token : str or None
        Required token (None: no token needed).
    loopback_only : bool
        Check that ``Host`` names a loopback address (use on loopback binds).
    max_body : int
        Largest request body (bytes).
    body_timeout : float
        Seconds the whole body has to arrive after the request head.
    """

    def __init__(self, app, token: str | None = None, *, loopback_only: bool = True,
                 max_body: int = MAX_BODY, body_timeout: float = BODY_TIMEOUT):
        self.app = app
        self.token = token
        self.loopback_only = loopback_only
        self.max_body = max_body
        self.body_timeout = body_timeout

    def _token_ok(self, scope, headers) -> bool:
        if self.token is None:
            return True
        want = self.token.encode()
        auth = headers.get("authorization", "")
        if auth[:7].lower() == "bearer " and hmac.compare_digest(auth[7:].strip().encode(), want):
            return True
        query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
        for given in query.get("token", ()):
            if hmac.compare_digest(given.encode(), want):
                return True
        if "cookie" in headers:
            cookie = SimpleCookie()
            try:
                cookie.load(headers["cookie"])
            except Exception:
                return False
            morsel = cookie.get(COOKIE)
            if morsel is not None and hmac.compare_digest(morsel.value.encode(), want):
                return True
        return False

    def _refusal(self, scope, headers) -> tuple[int, str] | None:
        host = headers.get("host", "")
        if self.loopback_only and not is_loopback(_host_only(host)):
            return 400, "bad Host header: this console answers only to loopback addresses"
        origin = headers.get("origin")
        if origin is not None:
            o = urlsplit(origin)
            if o.netloc.lower() != host.lower() or o.scheme not in ("http", "https"):
                return 403, "cross-origin request refused"
        if not self._token_ok(scope, headers):
            return 401, "missing or wrong token"
        if scope["type"] == "http" and scope["method"] not in ("GET", "HEAD"):
            ctype = headers.get("content-type", "").split(";")[0].strip().lower()
            if ctype != "application/json":
                return 415, "request bodies must be application/json"
            length = headers.get("content-length")
            if length is not None:
                try:
                    n = int(length)
                except ValueError:
                    return 400, "bad Content-Length"
                if n > self.max_body:
                    return 413, f"request body larger than {self.max_body} bytes"
        return None

    async def __call__(self, scope, receive, send):
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = _headers(scope)
        refusal = self._refusal(scope, headers)
        if refusal is not None:
            status, message = refusal
            if scope["type"] == "websocket":
                await _refuse_websocket(scope, receive, send, status, message)
            else:
                await _send_error(_with_security_headers(send), status, message)
            return
        if scope["type"] == "websocket":
            await self.app(scope, receive, send)
            return

        send = _with_security_headers(send)
        # read the whole (small) body first, refusing it as soon as it is too large or late:
        # every method's (a GET's body, which no route reads, trickled a byte at a time
        # would otherwise hold its connection open for ever)
        chunks, size, more = [], 0, True
        deadline = asyncio.get_running_loop().time() + self.body_timeout
        while more:
            try:
                message = await asyncio.wait_for(
                    receive(), deadline - asyncio.get_running_loop().time())
            except TimeoutError:
                await _send_error(send, 408, f"request body not received within "
                                  f"{self.body_timeout:g} s")
                return
            if message["type"] != "http.request":
                return  # the client went away
            chunk = message.get("body", b"")
            size += len(chunk)
            if size > self.max_body:
                await _send_error(send, 413, f"request body larger than {self.max_body} bytes")
                return
            chunks.append(chunk)
            more = message.get("more_body", False)
        replayed = False

        async def replay():
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": b"".join(chunks), "more_body": False}
            return await receive()

        await self.app(scope, replay, send)


#: Added to every HTTP response: no framing, no sniffing, no referrer (the URL may
#: carry the token), and only the console's own scripts and connections.
SECURITY_HEADERS = (
    (b"x-content-type-options", b"nosniff"),
    (b"x-frame-options", b"DENY"),
    (b"referrer-policy", b"no-referrer"),
    (b"content-security-policy",
     b"default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
     b"img-src 'self' data:; connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; "
     b"form-action 'none'"),
)


def _with_security_headers(send):
    async def wrapped(message):
        if message["type"] == "http.response.start":
            message = {**message, "headers": [*message.get("headers", ()), *SECURITY_HEADERS]}
        await send(message)

    return wrapped


async def _refuse_websocket(scope, receive, send, status: int, message: str) -> None:
    """Refuse a WebSocket handshake: an HTTP ``status`` where the server supports the
    ASGI denial response (uvicorn does), else a close with code 1008."""
    first = await receive()
    if first.get("type") != "websocket.connect":
        return
    if "websocket.http.response" in scope.get("extensions", {}):
        body = json.dumps({"detail": message, "errors": []}).encode()
        headers = [(b"content-type", b"application/json"),
                   (b"content-length", str(len(body)).encode())]
        if status == 401:
            headers.append((b"www-authenticate", b'Bearer realm="frictionlab"'))
        await send({"type": "websocket.http.response.start", "status": status,
                    "headers": headers})
        await send({"type": "websocket.http.response.body", "body": body})
    else:
        await send({"type": "websocket.close", "code": 1008, "reason": message})


async def _send_error(send, status: int, message: str) -> None:
    """A refusal; the connection is closed after it, so no refused client keeps one."""
    body = json.dumps({"detail": message, "errors": []}).encode()
    headers = [(b"content-type", b"application/json"),
               (b"content-length", str(len(body)).encode()), (b"connection", b"close")]
    if status == 401:
        headers.append((b"www-authenticate", b'Bearer realm="frictionlab"'))
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": body})
