"""API docs (Swagger UI), the favicon and the participant guide, all served by the service
itself: the pages work on a machine with no internet (FastAPI's defaults load Swagger UI from a
CDN). The Swagger UI bundle comes from the ``fastapi-offline`` package's static folder. No ReDoc:
its page fetches a logo from the internet."""

from __future__ import annotations

from pathlib import Path

import fastapi_offline
from fastapi import APIRouter, FastAPI, Request
from fastapi.openapi.docs import (
    get_swagger_ui_html,
    get_swagger_ui_oauth2_redirect_html,
)
from fastapi.responses import FileResponse, HTMLResponse
from fastapi.staticfiles import StaticFiles
from markdown_it import MarkdownIt

from server.api.security_headers import page_templates, with_nonce

ASSETS_DIR = Path(fastapi_offline.__file__).resolve().parent / "static"
ASSETS_URL = "/docs-assets"
DOCS_DIR = Path(__file__).resolve().parents[3] / "docs"
# Participant guides served as pages: name in the URL -> file under docs/.
GUIDES = {
    "agent-interface": "agent-interface.md",
    "submissions": "submissions.md",
    "scoring": "scoring.md",
}

templates = page_templates(Path(__file__).resolve().parents[2] / "templates")
router = APIRouter(include_in_schema=False)


def mount_docs_assets(app: FastAPI) -> None:
    app.mount(ASSETS_URL, StaticFiles(directory=ASSETS_DIR), name="docs-assets")


@router.get("/docs", response_class=HTMLResponse)
def swagger_ui(request: Request) -> HTMLResponse:
    page = get_swagger_ui_html(
        openapi_url=request.app.openapi_url,
        title=f"{request.app.title} · API",
        oauth2_redirect_url="/docs/oauth2-redirect",
        swagger_js_url=f"{ASSETS_URL}/swagger-ui-bundle.js",
        swagger_css_url=f"{ASSETS_URL}/swagger-ui.css",
        swagger_favicon_url="/favicon.ico",
    )
    return HTMLResponse(with_nonce(page.body.decode(), request.state.csp_nonce))


@router.get("/docs/oauth2-redirect", response_class=HTMLResponse)
def swagger_ui_redirect(request: Request) -> HTMLResponse:
    page = get_swagger_ui_oauth2_redirect_html()
    return HTMLResponse(with_nonce(page.body.decode(), request.state.csp_nonce))


@router.get("/favicon.ico")
def favicon() -> FileResponse:
    return FileResponse(ASSETS_DIR / "favicon.png", media_type="image/png")


@router.get("/guide/{name}", response_class=HTMLResponse)
def guide(request: Request, name: str) -> HTMLResponse:
    path = DOCS_DIR / GUIDES.get(name, "")
    if name not in GUIDES or not path.is_file():  # docs/ ships with the repository, not a wheel
        return HTMLResponse("no such guide", status_code=404)
    text = path.read_text(encoding="utf-8")
    # Links between the guides point at their pages, not at the .md files.
    for other, file in GUIDES.items():
        text = text.replace(f"]({file}", f"](/guide/{other}")
    body = MarkdownIt("commonmark").enable("table").render(text)
    return templates.TemplateResponse(request, "guide.html", {"body": body, "name": name})
