"""Browser-test fixtures: one seeded server and one headless Chromium for the whole session, a page per test."""

from collections.abc import Iterator

import pytest
from playwright.sync_api import Browser, Page, ViewportSize, expect, sync_playwright

from tests.backend_system.system_helpers import free_port
from tests.dependency_policy import require_program
from tests.frontend.editor_browser_helpers import CHROMIUM_PATH, SeededServer, launch_chromium, seeded_server

VIEWPORT: ViewportSize = {"width": 1440, "height": 900}
expect.set_options(timeout=10_000)  # the machine is shared: give slow renders room


@pytest.fixture(scope="session")
def review_url() -> str:
    """Where the seeded server says the 3D review is: a free loopback port a test may serve viser on."""
    return f"http://127.0.0.1:{free_port()}/"


@pytest.fixture(scope="session")
def seeded(tmp_path_factory: pytest.TempPathFactory, review_url: str) -> Iterator[SeededServer]:
    """A real `cama serve` on loopback with users ann, bob (annotators), lead and the painted site."""
    with seeded_server(tmp_path_factory.mktemp("editor-server"), review_url) as server:
        yield server


@pytest.fixture(scope="session")
def browser() -> Iterator[Browser]:
    """Headless Debian Chromium; skipped with the reason, or failed under CI, when it is not installed."""
    require_program(
        CHROMIUM_PATH,
        "the browser tests drive it through Playwright",
        "`make test` installs it: its chromium target installs Debian's chromium package",
    )
    with sync_playwright() as playwright:
        chromium = launch_chromium(playwright)
        yield chromium
        chromium.close()


@pytest.fixture
def page(browser: Browser) -> Iterator[Page]:
    """A fresh context (own session storage; CSP bypassed so Playwright may evaluate) and page; page errors fail."""
    context = browser.new_context(viewport=VIEWPORT, bypass_csp=True)
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.set_default_timeout(10_000)
    yield page
    context.close()
    assert not errors, f"uncaught errors in the page: {errors}"
