"""Helpers of the browser test: a private JupyterLab server, Debian's Chromium driven by Playwright,
and a kernel client that asks a notebook's kernel for reference renders.

Nothing here downloads anything: Playwright drives the system Chromium (``/usr/bin/chromium``, set
up by ``scripts/setup.sh``; ``SALAD_CHROMIUM`` points elsewhere), never a browser of its own
(``playwright install`` is not used). The server listens on 127.0.0.1 only, on a free port, with a
random token, and keeps its configuration, data, runtime files and settings in a temporary folder;
:meth:`LabServer.stop` ends that server (and, through it, its kernels) and nothing else.
"""
from __future__ import annotations

import base64
import io
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

#: Chromium's flags (Playwright adds ``--headless`` itself when ``headless=True``).
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync"]
#: JupyterLab's "Kernel Comms over subshells" setting (kernels-settings of apputils-extension).
SUBSHELL_PLUGIN = "@jupyterlab/apputils-extension:kernels-settings"
SUBSHELL_MODES = ("perCommTarget", "perComm", "disabled")   # the first is JupyterLab's default


def chromium_path() -> str | None:
    """The Chromium binary to drive: ``$SALAD_CHROMIUM``, else Debian's, else ``None``."""
    for cand in (os.environ.get("SALAD_CHROMIUM"), "/usr/bin/chromium", shutil.which("chromium"),
                 shutil.which("chromium-browser")):
        if cand and os.access(cand, os.X_OK):
            return cand
    return None


def unavailable_reason() -> str | None:
    """Why the browser test cannot run here, or ``None`` when it can."""
    if chromium_path() is None:
        return ("no Chromium at /usr/bin/chromium (scripts/setup.sh installs Debian's 'chromium' package when "
                "run as root; SALAD_CHROMIUM=PATH points to another binary)")
    for module, package in (("playwright.sync_api", "playwright"), ("jupyterlab", "jupyterlab"),
                            ("jupyter_client", "jupyter_client"), ("ipywidgets", "ipywidgets")):
        try:
            __import__(module)
        except ImportError:
            return f"the Python package {package!r} is not installed (bash scripts/setup.sh installs it)"
    return None


@contextmanager
def launch_chromium() -> Iterator:
    """The system Chromium (:func:`chromium_path`) launched headless by Playwright; on leaving, the browser
    is closed and Playwright stopped."""
    from playwright.sync_api import sync_playwright

    pw = sync_playwright().start()
    try:
        chromium = pw.chromium.launch(executable_path=chromium_path(), headless=True,
                                      args=[f for f in CHROMIUM_FLAGS if f != "--headless"])
        try:
            yield chromium
        finally:
            chromium.close()
    finally:
        pw.stop()


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# ------------------------------------------------------------------------------ the server
class LabServer:
    """A JupyterLab server of our own in ``root`` (a temporary folder), on 127.0.0.1.

    Parameters
    ----------
    root : Path
        The server's root folder (the notebooks under test are copied there).
    env : dict, optional
        Extra environment for the server and so its kernels (e.g. ``SALAD_QUICK=1``).
    startup_timeout : float
        Seconds to wait for the server to answer.
    """

    def __init__(self, root: Path, *, env: dict | None = None, startup_timeout: float = 90.0):
        self.root = Path(root)
        self.home = self.root.parent / f".{self.root.name}-jupyter"
        self.token = secrets.token_hex(16)
        self.port = free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        self.log_path = self.home / "server.log"
        self.runtime_dir = self.home / "runtime"
        self._extra_env = dict(env or {})
        self._timeout = startup_timeout
        self.proc: subprocess.Popen | None = None

    # ---------------------------------------------------------------- lifecycle
    def start(self) -> "LabServer":
        for sub in ("config", "data", "runtime", "settings", "workspaces"):
            (self.home / sub).mkdir(parents=True, exist_ok=True)
        # no announcements feed and no update check: the server stays off the network
        config = {"LabApp": {"news_url": None,
                             "check_for_updates_class": "jupyterlab.handlers.announcements.NeverCheckForUpdate",
                             "expose_app_in_browser": True, "extension_manager": "readonly",
                             "user_settings_dir": str(self.home / "settings"),
                             "workspaces_dir": str(self.home / "workspaces")},
                  "ServerApp": {"ip": "127.0.0.1", "port": self.port, "port_retries": 0, "open_browser": False,
                                "root_dir": str(self.root), "terminals_enabled": False,
                                # CI runs as root; the server still listens on 127.0.0.1 only, with a token
                                "allow_root": os.geteuid() == 0},
                  "IdentityProvider": {"token": self.token}}
        for name in ("jupyter_server_config.json", "jupyter_lab_config.json"):
            (self.home / "config" / name).write_text(json.dumps(config))
        # the page neither asks about nor fetches news
        notify = self.home / "settings" / "@jupyterlab" / "apputils-extension" / "notification.jupyterlab-settings"
        notify.parent.mkdir(parents=True, exist_ok=True)
        notify.write_text(json.dumps({"fetchNews": "false", "checkForUpdates": False}))
        env = {k: v for k, v in os.environ.items() if k not in ("MPLBACKEND", "JUPYTER_PLATFORM_DIRS")}
        env.update(JUPYTER_CONFIG_DIR=str(self.home / "config"), JUPYTER_DATA_DIR=str(self.home / "data"),
                   JUPYTER_RUNTIME_DIR=str(self.runtime_dir), JUPYTER_NO_CONFIG="", PYTHONUNBUFFERED="1")
        env.update(self._extra_env)
        with open(self.log_path, "wb") as log:
            # a session of its own: stop() can signal this server without touching anything else
            self.proc = subprocess.Popen([sys.executable, "-m", "jupyterlab"], cwd=self.root, env=env, stdout=log,
                                         stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True)
        deadline = time.monotonic() + self._timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"JupyterLab exited with code {self.proc.returncode}:\n{self.log_tail()}")
            try:
                self.api("GET", "/api/status")
                return self
            except (urllib.error.URLError, ConnectionError, OSError):
                time.sleep(0.5)
        self.stop()
        raise RuntimeError(f"JupyterLab did not answer within {self._timeout:.0f} s:\n{self.log_tail()}")

    def stop(self) -> None:
        """Shut down the kernels and the server we started (asked first, then SIGTERM, then SIGKILL)."""
        if self.proc is None or self.proc.poll() is not None:
            return
        try:
            for kernel in self.api("GET", "/api/kernels"):
                self.api("DELETE", f"/api/kernels/{kernel['id']}")
        except Exception:
            pass
        try:
            self.api("POST", "/api/shutdown")
            self.proc.wait(20)
        except Exception:
            pass
        for sig in (signal.SIGTERM, signal.SIGKILL):
            if self.proc.poll() is not None:
                break
            try:
                os.killpg(self.proc.pid, sig)   # our own session id: only this server's group
            except ProcessLookupError:
                break
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                pass

    def __enter__(self) -> "LabServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def log_tail(self, n: int = 40) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-n:])
        except OSError:
            return "(no log)"

    def log_text(self, since: int = 0) -> str:
        """The server's log (its kernels' stderr included) from byte ``since`` on."""
        if not self.log_path.exists():
            return ""
        with open(self.log_path, "rb") as f:
            f.seek(since)
            return f.read().decode(errors="replace")

    def log_size(self) -> int:
        return self.log_path.stat().st_size if self.log_path.exists() else 0

    # ---------------------------------------------------------------- REST
    def url(self, path: str) -> str:
        sep = "&" if "?" in path else "?"
        return f"{self.base}{path}{sep}token={self.token}"

    def api(self, method: str, path: str, body=None):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.base + path, data=data, method=method,
                                     headers={"Authorization": f"token {self.token}",
                                              "Content-Type": "application/json"})
        with urllib.request.urlopen(req, timeout=30) as resp:
            text = resp.read().decode()
        return json.loads(text) if text.strip() else None

    def set_subshells(self, mode: str) -> None:
        """JupyterLab's "Kernel Comms over subshells" for the pages opened from now on."""
        if mode not in SUBSHELL_MODES:
            raise ValueError(f"mode must be one of {SUBSHELL_MODES}, got {mode!r}")
        self.api("PUT", f"/lab/api/settings/{SUBSHELL_PLUGIN}", {"raw": json.dumps({"commsOverSubshells": mode})})

    def shutdown_kernels(self) -> None:
        for kernel in self.api("GET", "/api/kernels"):
            self.api("DELETE", f"/api/kernels/{kernel['id']}")

    def kernel_id(self, notebook: str) -> str:
        """The kernel of the session of ``notebook`` (a path relative to the root)."""
        for sess in self.api("GET", "/api/sessions"):
            if sess.get("path") == notebook and sess.get("kernel"):
                return sess["kernel"]["id"]
        raise LookupError(f"no kernel session for {notebook!r}")

    def kernel_client(self, kernel_id: str) -> "KernelProbe":
        return KernelProbe(self.runtime_dir / f"kernel-{kernel_id}.json")


# ------------------------------------------------------------------------------ the kernel
class KernelProbe:
    """A second client of a notebook's kernel (its connection file): runs code on the kernel's main
    shell thread and returns what the code printed as JSON on its last line."""

    def __init__(self, connection_file: Path):
        from jupyter_client import BlockingKernelClient

        deadline = time.monotonic() + 30
        while not Path(connection_file).exists():
            if time.monotonic() > deadline:
                raise FileNotFoundError(f"no kernel connection file {connection_file}")
            time.sleep(0.2)
        self.client = BlockingKernelClient(connection_file=str(connection_file))
        self.client.load_connection_file()
        self.client.start_channels()
        self.client.wait_for_ready(timeout=60)

    def run_json(self, code: str, timeout: float = 120.0):
        out: list[str] = []
        errors: list[str] = []

        def hook(msg):
            kind = msg["msg_type"]
            if kind == "stream" and msg["content"]["name"] == "stdout":
                out.append(msg["content"]["text"])
            elif kind == "error":
                errors.append("\n".join(msg["content"]["traceback"]))

        reply = self.client.execute_interactive(code, store_history=False, output_hook=hook, timeout=timeout)
        if errors or reply["content"]["status"] != "ok":
            raise RuntimeError("kernel probe failed:\n" + ("\n".join(errors) or str(reply["content"])))
        lines = "".join(out).strip().splitlines()
        return json.loads(lines[-1]) if lines else None

    def close(self) -> None:
        self.client.stop_channels()


# ------------------------------------------------------------------------------ images
def decode_png(data: bytes) -> np.ndarray:
    """PNG bytes -> ``(H, W, 3)`` uint8."""
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


def b64png(text: str) -> np.ndarray:
    return decode_png(base64.b64decode(text))


def pixel_agreement(a: np.ndarray, b: np.ndarray, tol: int = 24) -> float:
    """Fraction of pixels whose channels all differ by at most ``tol`` (0 when the sizes differ)."""
    if a.shape != b.shape:
        return 0.0
    return float((np.abs(a.astype(int) - b.astype(int)).max(axis=-1) <= tol).mean())


# ------------------------------------------------------------------------------ the page
JS_IMAGE_B64 = """async (sel) => {
  const img = document.querySelector(sel);
  if (!img || !img.src) return null;
  const blob = await (await fetch(img.src)).blob();
  return await new Promise((ok) => { const r = new FileReader(); r.onload = () => ok(r.result.split(',')[1]);
                                     r.readAsDataURL(blob); });
}"""

JS_NOTEBOOK_READY = """() => {
  const app = window.jupyterapp;
  const w = app && app.shell.currentWidget;
  if (!w || !w.sessionContext || !w.context || !w.context.isReady || !w.sessionContext.isReady) return null;
  const k = w.sessionContext.session && w.sessionContext.session.kernel;
  return k && k.status === 'idle' && k.connectionStatus === 'connected' ? {id: k.id, path: w.context.path} : null;
}"""

JS_RUN_ALL = """() => {
  window.__saladRun = null;
  window.jupyterapp.commands.execute('notebook:run-all-cells')
    .then((ok) => { window.__saladRun = {ok: ok}; }, (e) => { window.__saladRun = {error: String(e)}; });
}"""
