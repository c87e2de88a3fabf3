"""The realism rating app for people: a small FastAPI site over one pair set (``pairs.json``) that shows each
rater every pair once, the two sides' clips side by side, and stores the answers
(:class:`asset2sim.apps.realism.ratings.RatingStore`).

Pages: ``/`` asks a rater id; ``/rate/{rater}`` shows the rater's next pair (both views of each side as
looping videos with their posters), the question, Left / Right buttons, an optional 1-5 score and a
comment; the answer is posted to ``/rate/{rater}/answer``; when every pair is answered, a closing page.

Double-blind: no page names a method or a clip's file; clips are served by position only,
``/media/{rater}/{pair}/{left|right}/{view}/{video|poster}``, mapped on the server to the files
``pairs.json`` names (checked at start to be regular files inside the folder); which slot is on the left is
:func:`asset2sim.apps.realism.ratings.left_slot`. The time a pair is first shown and the time of the answer
are the server's clock.

Durability: each answer is committed to ``ratings.sqlite`` before the reply, then ``ratings.parquet`` is
rewritten (after every answer, at start and at shutdown), so a restart loses nothing. Re-posting an answer is
harmless (the stored one is kept). :func:`serve` listens on 127.0.0.1 unless told otherwise.

Protections, as a web app on a shared machine needs them (``docs/guide/realism.md``, "What the app refuses"):

- Host: a request whose ``Host`` header is not the address served, ``127.0.0.1``, ``localhost``, ``::1`` or a
  name given in ``allowed_hosts`` is refused (400, Starlette's ``TrustedHostMiddleware``): a web page whose
  name was rebound to this machine's address (DNS rebinding) cannot reach the app.
- Origin: an answer posted with an ``Origin`` other than the app's own (scheme and ``Host``) is refused with 403
  before its body is read; so is ``Origin: null``.
- CSRF token: every form carries a token, an HMAC-SHA256 of the rater id under a secret kept in
  ``ratings.sqlite`` (random, made once: a restart keeps open forms valid); an answer without the right token
  is refused with 403.
- Body size: an answer whose ``Content-Length`` exceeds :data:`MAX_FORM_BYTES` is refused with 413 unread; a
  chunked body is read only up to the cap.
- Escaping: every text from ``pairs.json`` or the request is HTML-escaped where it is shown.
"""

# no `from __future__ import annotations`: FastAPI reads the endpoints' annotations (Request) in create_app's scope
import contextlib
import hashlib
import hmac
import sqlite3
from contextlib import asynccontextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Sequence
from urllib.parse import parse_qs, quote

from asset2sim.apps.realism.pair_set import media_path
from asset2sim.apps.realism.ratings import RatingError, RatingStore, check_rater, side
from asset2sim.inert import CONTENT_SECURITY_POLICY, CSP_META, html_text
from asset2sim.package_data import package_yaml

if TYPE_CHECKING:
    from fastapi import FastAPI, Request
    from fastapi.responses import HTMLResponse, Response

#: Largest answer form accepted, bytes.
MAX_FORM_BYTES = 16_384
_KINDS = {"video": "video/webm", "poster": "image/png"}
#: Headers of every page: ``same-origin`` sends no referrer to another site, and lets a browser's form post carry
#: the app's own ``Origin`` (under ``no-referrer`` browsers send ``Origin: null``, which the app refuses).
_HEADERS = {"Cache-Control": "no-store", "Referrer-Policy": "same-origin", "X-Content-Type-Options": "nosniff",
            "Content-Security-Policy": CONTENT_SECURITY_POLICY + "; frame-ancestors 'none'"}
_STATUS = {"RATER_INVALID": 400, "PAIR_UNKNOWN": 404, "ANSWER_INVALID": 400, "PAIR_NOT_SHOWN": 409, "ANSWER_CONFLICT": 409,
           "ORIGIN_REFUSED": 403, "TOKEN_INVALID": 403, "ANSWER_TOO_LARGE": 413, "STORE_FAILED": 503}
#: Host names every app answers to (besides the address it serves and ``allowed_hosts``).
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")
#: Addresses that mean "every interface": not a name a request can carry.
_ANY_ADDRESS = ("", "0.0.0.0", "::", "*")

#: The style sheet and the pages' bodies (``str.format`` templates; every field HTML-escaped where it is filled).
_PAGES: dict[str, str] = package_yaml(__package__, "rating_pages.yaml")


def _page(title: str, body: str, status: int = 200) -> "HTMLResponse":
    from fastapi.responses import HTMLResponse

    doc = (f"<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">{CSP_META}<title>{html_text(title)}</title>"
           f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><style>{_PAGES['style']}</style></head>"
           f"<body>{body}</body></html>\n")
    return HTMLResponse(doc, status_code=status, headers=_HEADERS)


def _start_page(error: str = "", status: int = 200) -> "HTMLResponse":
    return _page("Realism rating", _PAGES["start"].format(
        message=f"<p class=\"error\" id=\"error\">{html_text(error)}</p>" if error else ""), status)


def form_token(secret: bytes, rater: str) -> str:
    """The CSRF token of ``rater``'s answer form: HMAC-SHA256 (hex) of the rater id under ``secret``."""
    return hmac.new(secret, b"asset2sim-rating-form\0" + rater.encode(), hashlib.sha256).hexdigest()


def allowed_host_names(host: str = "127.0.0.1", allowed_hosts: Sequence[str] = ()) -> list[str]:
    """The ``Host`` names the app answers to: :data:`LOOPBACK_HOSTS`, ``host`` (unless it means every
    interface) and ``allowed_hosts``, lower case, without ports, IPv6 addresses in brackets (as a ``Host``
    header writes them)."""
    names = [n.strip().strip("[]").lower() for n in (*LOOPBACK_HOSTS, host, *allowed_hosts)
             if n.strip().strip("[]") not in _ANY_ADDRESS]
    return list(dict.fromkeys(f"[{n}]" if ":" in n else n for n in names))


def _error_page(code: str, message: str, rater: str | None = None) -> "HTMLResponse":
    link = f"/rate/{quote(rater, safe='')}" if rater else "/"
    back = f"<p><a href=\"{link}\">{'Continue rating' if rater else 'Start'}</a></p>"
    return _page("Realism rating: error",
                 f"<h1>Not recorded</h1><p class=\"error\" id=\"error\">{html_text(message)}</p>{back}",
                 _STATUS.get(code, 400))


async def _answer(store: RatingStore, secret: bytes, rater: str, request: "Request") -> "Response":
    """An answer posted by ``rater``: Origin, size, form token and values checked, recorded, the next pair
    (a redirect) or an error page naming what was refused."""
    from fastapi.responses import RedirectResponse

    origin = request.headers.get("origin")
    if origin is not None and origin.lower() != f"{request.url.scheme}://{request.headers.get('host', '')}".lower():
        return _error_page("ORIGIN_REFUSED", "refused: the answer was sent from another site")
    length = request.headers.get("content-length")
    too_large = f"the answer is larger than {MAX_FORM_BYTES} bytes"
    if length is not None and (not length.strip().isdigit() or int(length) > MAX_FORM_BYTES):
        return _error_page("ANSWER_TOO_LARGE", too_large)
    body = bytearray()
    async for chunk in request.stream():  # a chunked body: read only up to the cap
        body += chunk
        if len(body) > MAX_FORM_BYTES:
            return _error_page("ANSWER_TOO_LARGE", too_large)
    try:
        form = {k: v[0] for k, v in parse_qs(body.decode("utf-8"), keep_blank_values=True).items()}
    except UnicodeDecodeError:
        return _error_page("ANSWER_INVALID", "the answer is not UTF-8 text")
    if not hmac.compare_digest(form.get("token", "").encode(), form_token(secret, rater).encode()):
        return _error_page("TOKEN_INVALID", "refused: the form is not one this app sent (reload the page and "
                                            "answer again)")
    try:
        check_rater(rater)
        index = int(form.get("pair", ""))
        if not 0 <= index < len(store.pairs):
            raise RatingError("PAIR_UNKNOWN", f"no pair {index}")
        score_text = form.get("score", "").strip()
        store.record(rater, store.pairs[index].pair_id, form.get("choice", ""), score=int(score_text) if score_text else None,
                     comment=form.get("comment", ""))
    except ValueError as exc:  # RatingError, or a number that is not one
        code, message = ((exc.code, str(exc)) if isinstance(exc, RatingError)
                         else ("ANSWER_INVALID", "pair and score must be whole numbers"))
        return _error_page(code, message, rater if code != "RATER_INVALID" else None)
    except sqlite3.Error as exc:  # the database failed under the app: the rater is told, nothing is pretended
        return _error_page("STORE_FAILED", f"the answer could not be stored ({exc}); tell the person running "
                                           "the study")
    store.sync_parquet()
    return RedirectResponse(f"/rate/{quote(rater, safe='')}", status_code=303, headers=_HEADERS)


def create_app(folder: Path | str, *, host: str = "127.0.0.1",
               allowed_hosts: Sequence[str] = ()) -> "FastAPI":
    """The rating app of the pair set in ``folder`` (``pairs.json``; answers in ``ratings.sqlite`` and
    ``ratings.parquet`` there).
    ``host``: the address served; requests must name it, a loopback name or one of ``allowed_hosts`` in their
    ``Host`` header (:func:`allowed_host_names`). At shutdown (the app's lifespan) ``ratings.parquet`` is
    synced and the store closed. Protections: the module docstring.

    Raises:
        FileNotFoundError: no ``pairs.json`` in ``folder``.
        PairSetError: ``pairs.json`` invalid, or a clip or poster it names missing or outside ``folder``.
        RatingsDatabaseError: ``ratings.sqlite`` damaged (naming it and what to do).
    """
    from fastapi import FastAPI, Request  # optional (the pipeline extra): imported when an app is made
    from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response
    from starlette.middleware.trustedhost import TrustedHostMiddleware

    store = RatingStore(folder)
    # (pair index, slot, view index, kind) -> the file pairs.json names (PairSetError when one is missing or outside the folder)
    media = {(i, slot, v, kind): media_path(store.folder, getattr(clip, kind)) for i, pair in enumerate(store.pairs)
             for slot in ("a", "b") for v, clip in enumerate(side(pair, slot).clips) for kind in _KINDS}  # video, poster
    secret = store.form_secret()

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        yield
        store.sync_parquet()
        store.close()

    app = FastAPI(title="Realism rating", docs_url=None, redoc_url=None, openapi_url=None, lifespan=lifespan)
    app.add_middleware(TrustedHostMiddleware, allowed_hosts=allowed_host_names(host, allowed_hosts), www_redirect=False)
    app.state.store = store

    @app.get("/", response_class=HTMLResponse)
    def start() -> HTMLResponse:
        return _start_page()

    @app.get("/rate")
    def begin(rater: str = "") -> Response:
        try:
            check_rater(rater.strip())
        except RatingError as exc:
            return _start_page(str(exc), 400)
        return RedirectResponse(f"/rate/{quote(rater.strip(), safe='')}", status_code=303, headers=_HEADERS)

    @app.get("/rate/{rater}", response_class=HTMLResponse)
    def rate(rater: str) -> HTMLResponse:
        try:
            shown = store.next_pair(rater)
        except RatingError as exc:
            return _start_page(str(exc), 400)
        done, total = store.progress(rater)
        if shown is None:
            return _page("Realism rating: done", _PAGES["done"].format(rater=html_text(rater), total=total))
        r, index = quote(rater, safe=""), store.index[shown.pair.pair_id]
        # each side's clips, by position only
        columns = []
        for position, slot in (("left", shown.left), ("right", shown.right)):
            videos = []
            for v, clip in enumerate(side(shown.pair, slot).clips):
                base = f"/media/{r}/{index}/{position}/{v}"
                videos.append(f"<video id=\"{position}-{v}\" autoplay loop muted playsinline controls preload=\"auto\" "
                              f"poster=\"{base}/poster\" width=\"{clip.width}\" height=\"{clip.height}\" "
                              f"title=\"{html_text(clip.view)} view\"><source src=\"{base}/video\" type=\"video/webm\">"
                              "</video>")
            columns.append(f"<div class=\"side\" id=\"side-{position}\"><h2>{position.capitalize()}</h2>{''.join(videos)}</div>")
        scores = "".join(f"<label><input type=\"radio\" name=\"score\" value=\"{s}\" id=\"score-{s}\"> {s}</label> "
                         for s in range(1, 6))
        return _page(f"Realism rating: pair {done + 1} of {total}", _PAGES["rating"].format(
            rater=html_text(rater), number=done + 1, total=total, category=html_text(shown.pair.category),
            columns="".join(columns), r=r, index=index, token=html_text(form_token(secret, rater)), scores=scores))

    @app.post("/rate/{rater}/answer")
    async def answer(rater: str, request: Request) -> Response:
        return await _answer(store, secret, rater, request)

    @app.get("/media/{rater}/{index}/{position}/{view}/{kind}")
    def clip_file(rater: str, index: int, position: str, view: int, kind: str) -> Response:
        path = None  # the clip or poster shown to ``rater`` at ``position`` of pair ``index`` (404 for anything else)
        if kind in _KINDS and position in ("left", "right") and 0 <= index < len(store.pairs):
            with contextlib.suppress(RatingError):
                shown = store.showing(rater, store.pairs[index].pair_id)
                path = media.get((index, getattr(shown, position), view, kind))
        if path is None:
            return Response("not found", status_code=404, media_type="text/plain")
        return FileResponse(path, media_type=_KINDS[kind], headers={"Cache-Control": "private, max-age=3600",
                                                                      "X-Content-Type-Options": "nosniff"})

    return app


def serve(folder: Path | str, host: str = "127.0.0.1", port: int = 8765, *, log_level: str = "warning",
          allowed_hosts: Sequence[str] = ()) -> None:
    """Serve the rating app of ``folder`` with uvicorn on ``host``:``port`` until interrupted (SIGINT or SIGTERM
    stop it gracefully: ``ratings.parquet`` is synced at shutdown); ``allowed_hosts``: more names the app
    answers to (:func:`create_app`). Blocks.

    Raises: FileNotFoundError, PairSetError (:func:`create_app`); OSError when the port cannot be bound
    (uvicorn exits via SystemExit then); KeyboardInterrupt re-raised by uvicorn after a graceful stop on Ctrl-C.
    """
    import uvicorn

    app = create_app(folder, host=host, allowed_hosts=allowed_hosts)
    store: RatingStore = app.state.store
    config = uvicorn.Config(app, host=host, port=port, log_level=log_level, lifespan="on", access_log=False)
    try:
        uvicorn.Server(config).run()
    finally:
        if not store.closed:  # not stopped through the lifespan (e.g. the port was taken)
            store.sync_parquet()
            store.close()
