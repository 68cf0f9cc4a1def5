"""One edit driven in the Jupyter explorer in a real JupyterLab, in headless Chromium (the harness of
tests/_browser.py): a person selects a word, types its re-weight, toggles a mirror, types a target prompt and
presses "Run edit"; the page then shows the result the kernel drew and the line of Python, and that line, run
in the kernel against the same pipeline, gives the same motion bit for bit. Tiny random weights, saved into
the server's folder. Skips (with the reason) where Chromium, Playwright or JupyterLab is missing;
``SALAD_BROWSER_SHOTS=DIR`` keeps screenshots."""
from __future__ import annotations

import base64
import hashlib
import json
import os
import textwrap
import time
from pathlib import Path

import pytest

from _browser import JS_IMAGE_B64, JS_NOTEBOOK_READY, JS_RUN_ALL, LabServer, launch_chromium, unavailable_reason

REASON = unavailable_reason()
if REASON:
    pytest.skip(REASON, allow_module_level=True)

pytestmark = [pytest.mark.browser, pytest.mark.slow]

SOURCE = "a man raises his right hand high"
TARGET = "a man raises his left hand high"
CELLS = [
    f"""\
    %matplotlib inline
    import json, hashlib
    import numpy as np
    from salad_core.attention import CaptureConfig
    from salad_core.pipeline import SaladPipeline
    from salad_viz.widgets import explore_attention
    pipe = SaladPipeline.from_pretrained("tiny")
    out = pipe({SOURCE!r}, lengths=24, num_steps=4, seed=0, capture_attention=CaptureConfig(mode="full"))
    """,
    """\
    ex = explore_attention(out.attention, None, out.joints[0], editor=pipe, backend="raster", size=(200, 170))
    ex
    """,
    "print(ex.uid)",
]
KERNEL_CHECK = """
import salad_core.attention as _A
_ns = {"pipe": pipe, **{n: getattr(_A, n) for n in ("WordSwap", "Refine", "Reweight", "Mirror", "CaptureConfig")}}
_want = eval(ex.last_code, _ns)
print(json.dumps({"code": ex.last_code, "status": ex.edit_status.value,
                  "result_sha": hashlib.sha256(ex.result.value).hexdigest(),
                  "same": all(np.array_equal(getattr(_want, b).features, getattr(ex.last_edit, b).features)
                              and all(np.array_equal(p, q) for p, q in zip(getattr(_want, b).joints,
                                                                          getattr(ex.last_edit, b).joints))
                              for b in ("source", "edited"))}))
"""


@pytest.fixture(scope="module")
def browser():
    with launch_chromium() as chromium:
        yield chromium


def _shot(page, label: str) -> None:
    folder = os.environ.get("SALAD_BROWSER_SHOTS")
    if folder:
        Path(folder).mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(Path(folder) / f"explorer_edit_{label}.png"), full_page=True)


def _wait(probe, expression: str, want, message: str, timeout_s: float = 60.0) -> None:
    """Poll the kernel until ``expression`` equals ``want``."""
    deadline = time.monotonic() + timeout_s
    while (got := probe.run_json(f"print(json.dumps({expression}))")) != want:
        assert time.monotonic() < deadline, f"{message}: {expression} = {got!r}, want {want!r}"
        time.sleep(0.3)


def test_one_edit_from_the_explorer_in_jupyterlab(tmp_path, browser, make_tiny_pipeline):
    root = tmp_path / "root"
    root.mkdir()
    make_tiny_pipeline(seed=0).save_pretrained(root / "tiny")
    cells = [{"cell_type": "code", "id": f"cell-{i}", "metadata": {}, "execution_count": None, "outputs": [],
              "source": textwrap.dedent(src)} for i, src in enumerate(CELLS)]
    (root / "edit.ipynb").write_text(json.dumps({"cells": cells, "nbformat": 4, "nbformat_minor": 5, "metadata": {
        "kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"}}}))
    with LabServer(root, env={"OMP_NUM_THREADS": "1"}) as lab:
        context = browser.new_context(viewport={"width": 1400, "height": 1300})
        context.set_default_timeout(120_000)
        probe = None
        try:
            page = context.new_page()
            page.goto(lab.url("/lab/tree/edit.ipynb?reset"), wait_until="domcontentloaded", timeout=180_000)
            ready = page.wait_for_function(JS_NOTEBOOK_READY, polling=500, timeout=180_000).json_value()
            page.evaluate(JS_RUN_ALL)
            page.wait_for_function("() => window.__saladRun !== null", polling=1000, timeout=300_000)
            assert page.evaluate("() => window.__saladRun").get("ok") is not False
            page.wait_for_selector(".salad-explorer-run", timeout=120_000)
            probe = lab.kernel_client(ready["id"])
            uid = probe.run_json("print(json.dumps(ex.uid))")
            box = f".salad-explorer-id-{uid}"
            _shot(page, "1-open")
            # as a person does it: the word "high", its re-weight typed as -1, mirror the arms, a target, run
            page.locator(f"{box} .salad-explorer-words select option", has_text="high").first.click()
            _wait(probe, "ex.selected_words", ["high"], "the word selection did not reach the kernel")
            readout = page.locator(f"{box} .salad-explorer-reweight-high .widget-readout")
            readout.click()
            page.keyboard.press("Control+A")
            page.keyboard.type("-1")
            page.keyboard.press("Enter")
            page.locator(f"{box} .salad-explorer-mirror-arms").click()
            target = page.locator(f"{box} .salad-explorer-target input")
            target.fill(TARGET)
            target.press("Enter")
            _wait(probe, "[ex.target.value, ex.reweight_slider('high').value, ex.mirror_arms.value]",
                  [TARGET, -1.0, True], "the controls did not reach the kernel")
            page.locator(f"{box} .salad-explorer-run").click()
            deadline = time.monotonic() + 180
            while probe.run_json("print(json.dumps(ex.last_code is not None and not ex.run.disabled))") is not True:
                assert time.monotonic() < deadline, "the edit did not run"
                time.sleep(0.5)
            state = probe.run_json(KERNEL_CHECK)
            assert state["status"] == "" and state["same"], state
            assert state["code"] == (f'pipe.edit("{SOURCE}", target="{TARGET}", edits=[WordSwap(), '
                                     'Reweight(words="high", scale=-1), Mirror(parts="arms")], lengths=24, seed=0, '
                                     'num_steps=4, capture_attention=CaptureConfig(mode="full"))')
            # the page shows the line and the kernel's result figure
            page.wait_for_function(f"""() => {{ const e = document.querySelector('{box} .salad-explorer-code pre');
                                       return e && e.textContent.includes('Mirror(parts="arms")'); }}""")
            assert page.locator(f"{box} .salad-explorer-code pre").inner_text().strip() == state["code"]
            deadline = time.monotonic() + 60
            while True:
                data = page.evaluate(JS_IMAGE_B64, f"{box} img.salad-explorer-result, {box} .salad-explorer-result img")
                if data and hashlib.sha256(base64.b64decode(data)).hexdigest() == state["result_sha"]:
                    break
                assert time.monotonic() < deadline, "the page does not show the kernel's result figure"
                time.sleep(0.3)
            page.locator(f"{box} .salad-explorer-result").scroll_into_view_if_needed()
            _shot(page, "2-edited")
        finally:
            if probe is not None:
                probe.close()
            context.close()
