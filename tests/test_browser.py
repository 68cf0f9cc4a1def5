"""The notebooks and the attention explorer in a real JupyterLab, in headless Chromium.

The other notebook tests execute notebooks without a browser, so they cannot see what only a browser
session does: JupyterLab sends widget messages over kernel subshells (ipykernel 7 then runs widget
callbacks on other threads), renders the widgets, and the user clicks. This module starts its own
JupyterLab on 127.0.0.1 (a free port, a token, a temporary root holding copies of the notebooks),
opens the notebooks in Debian's Chromium through Playwright, runs every cell, checks that no cell
failed and that the widgets rendered, then drives the explorer's controls (words, layers, steps,
frame, play) under each "Kernel Comms over subshells" setting and compares the skeleton image the
browser shows after each interaction with a render of that frame made directly in the kernel.

Skips (with the reason) where Chromium, Playwright or JupyterLab is missing. Environment:
``SALAD_BROWSER_SHOTS=DIR`` saves a screenshot of each page state there.
"""
from __future__ import annotations

import base64
import hashlib
import json
import os
import shutil
import textwrap
import time
from pathlib import Path

import pytest

from _browser import (JS_IMAGE_B64, JS_NOTEBOOK_READY, JS_RUN_ALL, SUBSHELL_MODES, SUBSHELL_PLUGIN, LabServer, b64png,
                      decode_png, launch_chromium, pixel_agreement, unavailable_reason)

REASON = unavailable_reason()
if REASON:
    pytest.skip(REASON, allow_module_level=True)

pytestmark = [pytest.mark.browser, pytest.mark.slow]

NOTEBOOKS_DIR = Path(__file__).resolve().parents[1] / "notebooks"
REPO_NOTEBOOKS = ["00_quickstart.ipynb", "01_attention_maps.ipynb"]
EXPLORER_NB = "explorer.ipynb"
PROMPT = "a man jumps forward and then walks"
#: a browser image agrees with the kernel's render when this share of pixels match (max channel
#: difference <= 24 of 255); a context used from the wrong thread gives black frames or noise
AGREEMENT = 0.98
#: what VTK prints when a render window is used from a thread its context is not current on
GL_ERROR = "Frame buffer object was not initialized correctly"

EXPLORER_CELLS = [
    # the first session generates (the explorer takes the pipeline's AttentionMaps); later sessions
    # reuse its arrays (the explorer takes a plain array and its axes) and skip loading the model
    f"""\
    %matplotlib inline
    from pathlib import Path
    import numpy as np
    from salad_viz.widgets import explore_attention
    CACHE = Path("explorer_data.npz")
    if CACHE.exists():
        saved = np.load(CACHE)
        attention, joints, axes = saved["attention"], saved["joints"], "slhnpw"
        tokens = [str(t) for t in saved["tokens"]]
    else:
        from salad_core.attention import CaptureConfig
        from salad_core.pipeline import SaladPipeline
        pipe = SaladPipeline.from_pretrained()
        out = pipe({PROMPT!r}, lengths=60, num_steps=10, seed=0, capture_attention=CaptureConfig(mode="full"))
        attention, tokens, joints, axes = out.attention, out.attention.tokens(0), out.joints[0], "pnw"
        np.savez(CACHE, attention=out.attention.full(0), tokens=np.array(tokens), joints=joints)
    """,
    """\
    ex = explore_attention(attention, tokens, joints, "humanml3d", axes=axes, size=(320, 260))
    ex
    """,
    "print(ex.uid, ex.backend, ex.axes, ex.selected_words)",
]

# Defined once in the kernel: the explorer's state, and a reference render of a given selection
# made on the kernel's main thread by a renderer of its own (from the public functions, not from the
# explorer's cached colours).
KERNEL_HELPERS = '''
import base64, hashlib, json, threading
import numpy as np
from salad_viz.attention import joint_attention_colors, reduce_attention
from salad_viz.render import SkeletonRenderer
from salad_viz.widgets import AttentionExplorer, _png

_salad_renderers = {}

def _salad_state(uid):
    ex = AttentionExplorer.find(uid)
    return dict(words=ex.selected_words, layers=None if ex.layers is None else list(ex.layers.value),
                steps=None if ex.steps is None else list(ex.steps.value), frame=int(ex.frame.value),
                status=ex.status.value, backend=ex.backend, drawn=ex.drawn,
                skeleton_sha=hashlib.sha256(ex.skeleton_view.value).hexdigest(),
                heatmap_sha=hashlib.sha256(ex.heatmap.value).hexdigest(),
                threads=sorted(t.name for t in threading.enumerate()))

def _salad_reference(uid, words, layers, steps, frame):
    ex = AttentionExplorer.find(uid)
    red = reduce_attention(ex.attention, ex.axes, layers=layers, batch=ex.batch,
                           steps=None if steps is None else (steps[0], steps[1] + 1))
    ids = sorted({i for group in ex.word_ids(*words) for i in group})
    colors = joint_attention_colors(red[:, :, ids].sum(2), ex.skeleton, len(ex.joints),
                                    frames_per_latent=ex.fpl, cmap=ex.cmap)
    key = (tuple(ex.size), ex.backend)
    if key not in _salad_renderers:
        _salad_renderers[key] = SkeletonRenderer(ex.skeleton, size=ex.size, backend=ex.backend)
    img = _salad_renderers[key].render(ex.joints, frame, view=ex.view, joint_colors=colors, title=f"frame {frame}")
    return base64.b64encode(_png(img)).decode()
'''


def _explorer_notebook() -> dict:
    cells = [{"cell_type": "code", "metadata": {}, "execution_count": None, "outputs": [],
              "source": textwrap.dedent(src)} for src in EXPLORER_CELLS]
    return {"cells": cells, "nbformat": 4, "nbformat_minor": 5,
            "metadata": {"kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"}}}


# ------------------------------------------------------------------------------ fixtures
@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    root = tmp_path_factory.mktemp("lab") / "root"
    root.mkdir()
    for name in REPO_NOTEBOOKS:
        shutil.copy(NOTEBOOKS_DIR / name, root / name)
    (root / EXPLORER_NB).write_text(json.dumps(_explorer_notebook(), indent=1))
    from salad_viz.render import offscreen_available

    # probe OpenGL once here rather than in every kernel (the explorer uses pyvista where it works)
    backend = "pyvista" if offscreen_available() else "raster"
    server = LabServer(root, env={"SALAD_QUICK": "1", "SALAD_NOTEBOOK_OUT": str(root / "outputs"),
                                  "SALAD_VIZ_BACKEND": backend})
    server.start()
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture(scope="module")
def browser():
    with launch_chromium() as chromium:
        yield chromium


@pytest.fixture
def shots(request):
    """``save(page, label)``: a screenshot under $SALAD_BROWSER_SHOTS (when set)."""
    folder = os.environ.get("SALAD_BROWSER_SHOTS")

    def save(page, label: str) -> None:
        if folder:
            Path(folder).mkdir(parents=True, exist_ok=True)
            name = f"{request.node.name}-{label}".replace("/", "_").replace("[", "-").replace("]", "")
            page.screenshot(path=str(Path(folder) / f"{name}.png"), full_page=True)
    return save


class Session:
    """One notebook open in its own browser context, with the subshell setting given."""

    def __init__(self, browser, lab: LabServer, notebook: str, subshells: str):
        lab.shutdown_kernels()            # every session starts from a fresh kernel
        lab.set_subshells(subshells)
        self.lab, self.notebook = lab, notebook
        self.log_start = lab.log_size()
        self.context = browser.new_context(viewport={"width": 1500, "height": 1100})
        # generous: on a loaded 2-core machine JupyterLab's bundles take a while to load
        self.context.set_default_timeout(120_000)
        self.page = self.context.new_page()
        # ?reset: a fresh workspace, so the tabs of earlier sessions are not reopened (with kernels)
        self.page.goto(lab.url(f"/lab/tree/{notebook}?reset"), wait_until="domcontentloaded", timeout=180_000)
        ready = self.page.wait_for_function(JS_NOTEBOOK_READY, polling=500, timeout=180_000).json_value()
        assert ready["path"] == notebook
        self.kernel_id = ready["id"]
        # the page runs with the setting asked for
        loaded = self.page.evaluate(f"""async () => (await window.jupyterapp.serviceManager.settings.fetch(
            '{SUBSHELL_PLUGIN}')).settings.commsOverSubshells""")
        assert loaded == subshells, f"JupyterLab loaded commsOverSubshells={loaded!r}, asked for {subshells!r}"

    def run_all(self, timeout_s: float) -> dict:
        """Run every cell, save, and return the saved notebook (with outputs)."""
        self.page.evaluate(JS_RUN_ALL)
        self.page.wait_for_function("() => window.__saladRun !== null", polling=1000, timeout=timeout_s * 1000)
        result = self.page.evaluate("() => window.__saladRun")
        self.page.evaluate("() => window.jupyterapp.commands.execute('docmanager:save')")
        deadline = time.monotonic() + 30
        while True:
            nb = json.loads((self.lab.root / self.notebook).read_text())
            counts = [c.get("execution_count") for c in nb["cells"] if c["cell_type"] == "code"]
            if all(counts) or time.monotonic() > deadline:
                break
            time.sleep(0.5)
        nb["_run_result"] = result
        return nb

    def kernel_log(self) -> str:
        """What the server and its kernels logged since this session opened."""
        return self.lab.log_text(self.log_start)

    def close(self) -> None:
        self.context.close()


def _cell_failures(nb: dict) -> list[str]:
    failures = []
    for i, cell in enumerate(nb["cells"]):
        if cell["cell_type"] != "code":
            continue
        if cell.get("execution_count") is None:
            failures.append(f"cell {i} did not run")
        for o in cell.get("outputs", []):
            if o.get("output_type") == "error":
                failures.append(f"cell {i}: {o.get('ename')}: {o.get('evalue')}")
    return failures


def _widget_outputs(nb: dict) -> int:
    return sum("application/vnd.jupyter.widget-view+json" in o.get("data", {})
               for c in nb["cells"] if c["cell_type"] == "code" for o in c.get("outputs", []))


def _check_widgets_rendered(page, expected: int) -> None:
    """Every widget output is a rendered view (no 'Error displaying widget', nothing left loading)."""
    if not expected:
        return
    rendered = "document.querySelectorAll('.jp-OutputArea-output .jupyter-widgets').length"
    page.wait_for_function(f"() => {rendered} >= {expected}", polling=500, timeout=60_000)
    text = page.inner_text(".jp-NotebookPanel:not(.lm-mod-hidden) .jp-Notebook")
    assert "Error displaying widget" not in text and "Loading widget..." not in text


# ------------------------------------------------------------------------------ the explorer
class ExplorerDriver:
    """Drives one explorer in the page and checks it against the kernel after each interaction."""

    def __init__(self, session: Session, uid: str):
        self.s, self.page, self.uid = session, session.page, uid
        self.root = f".salad-explorer-id-{uid}"
        self.probe = session.lab.kernel_client(session.kernel_id)
        self.probe.run_json(KERNEL_HELPERS + "\nprint(json.dumps(1))")
        self.checked: list[dict] = []

    def state(self) -> dict:
        return self.probe.run_json(f"print(json.dumps(_salad_state({self.uid!r})))")

    def browser_image(self, part: str) -> bytes | None:
        data = self.page.evaluate(JS_IMAGE_B64, f"{self.root} .salad-explorer-{part} img, "
                                                f"{self.root} img.salad-explorer-{part}")
        return None if data is None else base64.b64decode(data)

    def settle(self, want: dict, timeout_s: float = 60.0) -> dict:
        """Wait until the kernel's controls equal ``want`` and the browser shows the kernel's images."""
        deadline = time.monotonic() + timeout_s
        while True:
            st = self.state()
            shown = self.browser_image("skeleton")
            heat = self.browser_image("heatmap")
            same = (shown is not None and hashlib.sha256(shown).hexdigest() == st["skeleton_sha"]
                    and heat is not None and hashlib.sha256(heat).hexdigest() == st["heatmap_sha"])
            drawn = st["drawn"] or {}
            current = {k: st[k] for k in ("words", "layers", "steps", "frame")}
            if same and drawn == current and all(st[k] == v for k, v in want.items()):
                return st | {"shown": shown}
            if time.monotonic() > deadline:
                raise AssertionError(f"the explorer did not settle on {want} within {timeout_s:.0f} s: kernel state "
                                     f"{ {k: st[k] for k in want} }, drawn {st['drawn']}, "
                                     f"browser image up to date: {same}, status {st['status']!r}")
            time.sleep(0.3)

    def check(self, label: str, want: dict, shots) -> dict:
        st = self.settle(want)
        assert st["status"] == "", st["status"]
        ref = b64png(self.probe.run_json(
            f"print(json.dumps(_salad_reference({self.uid!r}, {st['words']!r}, {st['layers']!r}, {st['steps']!r}, "
            f"{st['frame']})))"))
        shown = decode_png(st["shown"])
        agree = pixel_agreement(shown, ref)
        shots(self.page, label)
        # the reference itself must show a body: many pixels away from the flat background
        background = ref[0, 0].astype(int)
        assert (abs(ref.astype(int) - background).max(-1) > 40).mean() > 0.02
        self.checked.append(dict(label=label, frame=st["frame"], words=st["words"], agreement=round(agree, 4)))
        assert agree >= AGREEMENT, (f"{label}: the browser's skeleton image agrees with the kernel's render of frame "
                                    f"{st['frame']} on {agree:.1%} of the pixels (need {AGREEMENT:.0%})")
        return st

    # --- the controls, as a person uses them
    def _option(self, control: str, text: str):
        return self.page.locator(f"{self.root} .salad-explorer-{control} select option", has_text=text)

    def click_option(self, control: str, text: str, modifiers=None) -> None:
        self._option(control, text).first.click(modifiers=modifiers or [])

    def select_options(self, control: str, labels: list[str]) -> None:
        self.page.locator(f"{self.root} .salad-explorer-{control} select").select_option(label=labels)

    def type_readout(self, control: str, text: str) -> None:
        readout = self.page.locator(f"{self.root} .salad-explorer-{control} .widget-readout")
        readout.click()
        self.page.keyboard.press("Control+A")
        self.page.keyboard.type(text)
        self.page.keyboard.press("Enter")

    def arrow_key(self, control: str, key: str = "ArrowRight") -> None:
        handle = self.page.locator(f"{self.root} .salad-explorer-{control} .noUi-handle").first
        handle.focus()
        self.page.keyboard.press(key)

    def play_for(self, seconds: float) -> None:
        play_pause = self.page.locator(f"{self.root} .salad-explorer-play button").first
        play_pause.click()                           # play (the button turns into pause)
        time.sleep(seconds)
        play_pause.click()                           # pause

    def close(self) -> None:
        self.probe.close()


def _find_explorers(page) -> list[str]:
    classes = page.evaluate("() => Array.from(document.querySelectorAll('.salad-explorer')).map(e => e.className)")
    return [c.split("salad-explorer-id-")[1].split()[0] for c in classes if "salad-explorer-id-" in c]


# ------------------------------------------------------------------------------ tests
@pytest.mark.parametrize("notebook", REPO_NOTEBOOKS)
def test_notebook_runs_in_jupyterlab(notebook, lab, browser, shots):
    """Every cell of the notebook runs in JupyterLab without an error; its widgets render; an
    explorer it shows follows its frame control."""
    session = Session(browser, lab, notebook, SUBSHELL_MODES[0])
    try:
        nb = session.run_all(timeout_s=240)
        shots(session.page, "run")
        failures = _cell_failures(nb)
        assert not failures, f"{notebook}: {failures} (run result {nb['_run_result']})"
        assert nb["_run_result"] == {"ok": True}
        _check_widgets_rendered(session.page, _widget_outputs(nb))
        for uid in _find_explorers(session.page):
            ex = ExplorerDriver(session, uid)
            try:
                st = ex.check("explorer-open", {}, shots)
                last = int(session.page.evaluate(f"() => 0") or 0)
                ex.type_readout("frame", str(max(st["frame"] + 7, 7)))
                ex.check("explorer-frame", {"frame": max(st["frame"] + 7, 7)}, shots)
                del last
            finally:
                ex.close()
    finally:
        session.close()
    assert "Frame buffer object was not initialized correctly" not in lab.log_text()


@pytest.mark.parametrize("subshells", SUBSHELL_MODES)
def test_explorer_follows_every_control(subshells, lab, browser, shots):
    """Words (Ctrl-click and plain click), layers, steps, frame (typed and arrow key) and play: after
    each, the browser shows the kernel's image and that image is a correct render of the frame."""
    session = Session(browser, lab, EXPLORER_NB, subshells)
    try:
        t0 = time.perf_counter()
        nb = session.run_all(timeout_s=180)
        assert not _cell_failures(nb), _cell_failures(nb)
        _check_widgets_rendered(session.page, 1)
        uids = _find_explorers(session.page)
        assert len(uids) == 1, uids
        ex = ExplorerDriver(session, uids[0])
        try:
            st = ex.check("open", {"words": ["jumps"], "layers": [0, 1, 2, 3, 4], "steps": [0, 9], "frame": 0},
                          shots)
            assert st["backend"] in ("pyvista", "raster")
            # the hint says how to select several words
            assert "Ctrl-click" in session.page.inner_text(ex.root)
            ex.click_option("words", "walks", modifiers=["Control"])
            ex.check("ctrl-click-walks", {"words": ["jumps", "walks"]}, shots)
            ex.select_options("layers", ["layer 2", "layer 4"])
            ex.check("layers-2-4", {"layers": [2, 4]}, shots)
            ex.type_readout("steps", "2 - 7")
            ex.check("steps-2-7", {"steps": [2, 7]}, shots)
            ex.type_readout("frame", "30")
            ex.check("frame-30", {"frame": 30}, shots)
            ex.arrow_key("frame", "ArrowRight")
            ex.check("frame-31", {"frame": 31}, shots)
            ex.click_option("words", "forward")
            ex.check("click-forward", {"words": ["forward"]}, shots)
            ex.play_for(0.8)                         # 20 fps from frame 31: paused before the end (59)
            st = ex.check("played", {}, shots)
            assert st["frame"] > 31, f"play did not move the frame forward (frame {st['frame']})"
            threads = [t for t in st["threads"] if t.startswith("subshell-")]
            if subshells == "disabled":
                assert not threads, threads
            else:
                assert threads, f"with comms over subshells ({subshells}) the kernel runs no subshell thread"
            print(f"{subshells}: {time.perf_counter() - t0:.1f} s, backend {st['backend']}, subshell threads "
                  f"{len(threads)}, agreement {[c['agreement'] for c in ex.checked]}")
        finally:
            ex.close()
        assert GL_ERROR not in session.kernel_log()
    finally:
        session.close()
