"""salad_viz.export_explorer: the attention explorer as one self-contained HTML file.

Without a browser: the numbers the page embeds are the captured maps' (to the page's rounding), a full capture
of the longest motion stays under 8 MB, the inline Jupyter view is the page in an ``<iframe srcdoc>``, and bad
inputs are refused. In headless Chromium (Debian's, through Playwright; no browser download), from a file://
URL with every network request refused and recorded: the page plays, scrubbing moves the skeleton, selecting
another word changes the heatmap's numbers and the bones' colours, the maps the page computes equal
``AttentionMaps``' for words, layers and steps, an edit shows both motions on one colour scale, the inline
iframe works (also in a saved notebook reopened in JupyterLab), and nothing is fetched.
``SALAD_BROWSER_SHOTS=DIR`` keeps screenshots of the page states.
"""
from __future__ import annotations

import html
import json
import os
import re
import time
from pathlib import Path

import numpy as np
import pytest

from salad_core.attention import CaptureConfig
from salad_viz import ExplorerPage, export_explorer
from salad_viz.explorer_html import MAX_BYTES, explorer_data

PROMPT = "a man jumps forward and then walks forward, while waving his arms"
TARGET = "a man jumps forward and then runs forward, while waving his arms"
#: the longest motion the model makes (196 frames; 200 is not a multiple of 4 frames per latent frame below 196)
LONGEST = 196


def _embedded(page: str) -> dict:
    """The JSON the page carries."""
    text = re.search(r'<script id="salad-data" type="application/json">(.*?)</script>', page, re.S).group(1)
    return json.loads(text)


def _full_reference(maps, b: int, steps, layers, cols) -> np.ndarray:
    """``(7, N')``: the mean over ``steps`` x ``layers`` x heads of a full capture, summed over ``cols``."""
    full = np.asarray(maps.full(b), dtype=np.float64)[np.ix_(steps, layers)]      # (s, l, H, N', P, W)
    return full.mean(axis=(0, 1, 2))[..., cols].sum(-1).T


# ------------------------------------------------------------------------------ fixtures
@pytest.fixture(scope="module")
def tiny_full(pipe):
    """A full capture (every step, layer and head) of the tiny pipeline: (joints, AttentionMaps)."""
    out = pipe(PROMPT, lengths=48, num_steps=6, seed=0, capture_attention=CaptureConfig(mode="full"))
    return out.joints[0], out.attention


# ------------------------------------------------------------------------------ no browser
def test_embedded_numbers_are_the_captured_maps(tiny_full):
    joints, maps = tiny_full
    page = export_explorer(maps, None, joints, model="tiny")
    assert isinstance(page, ExplorerPage) and isinstance(page, str)
    data = _embedded(page)
    (panel,) = data["panels"]
    unit = data["scale"]
    words, s, layers, parts, n = panel["shape"]
    assert (s, layers, parts, n) == (6, len(maps.captured_layers), 7, 48 // 4)
    att = np.asarray(panel["att"], dtype=np.float64).reshape(panel["shape"]) * unit
    assert [w["text"] for w in panel["words"]] == maps.words(0)           # the "," token is not a word
    for k, word in enumerate(panel["words"]):
        assert word["tokens"] == maps.word_columns(0, k)
        for step in range(s):
            for layer in range(layers):
                ref = _full_reference(maps, 0, [step], [layer], word["tokens"])
                np.testing.assert_allclose(att[k, step, layer], ref, atol=unit / 2 + 1e-7)
    # the default view (all steps, layers, heads) is AttentionMaps.word_map
    ref = maps.word_map(0, "jumps")
    k = [w["text"] for w in panel["words"]].index("jumps")
    np.testing.assert_allclose(att[k].mean(axis=(0, 1)), ref, atol=unit)
    joints_mm = np.asarray(panel["joints"]).reshape(len(joints), -1, 3) * data["jointScale"]
    np.testing.assert_allclose(joints_mm, joints, atol=5e-4 + 1e-9)
    assert data["steps"]["total"] == 6 and data["layers"] == [str(i) for i in maps.captured_layers]
    assert data["prompt"] == PROMPT and data["model"] == "tiny"
    assert panel["selected"] == [maps.words(0).index("jumps")]            # the first content word


def test_mean_capture_and_plain_arrays(pipe):
    out = pipe(PROMPT, lengths=40, num_steps=4, seed=1, capture_attention=True)
    maps = out.attention
    data = explorer_data(maps, None, out.joints[0])
    assert data["steps"] is None and len(data["layers"]) == len(maps.captured_layers)
    (panel,) = data["panels"]
    att = panel["att"] * data["scale"]
    for layer_pos, layer in enumerate(maps.captured_layers):
        np.testing.assert_allclose(att[2, 0, layer_pos], maps.select(layers=[layer]).word_map(0, "jumps"),
                                   atol=data["scale"] / 2 + 1e-7)
    # a (P, N', W) array has neither steps nor layers
    plain = explorer_data(maps.cross_map(0), maps.tokens(0), out.joints[0], words=["jumps", "walks"])
    assert plain["steps"] is None and plain["layers"] is None and plain["heads"] is None
    assert plain["panels"][0]["shape"][1:3] == [1, 1]
    assert [plain["panels"][0]["words"][i]["text"] for i in plain["panels"][0]["selected"]] == ["jumps", "walks"]


def test_longest_full_capture_stays_under_8_mb():
    """A full capture of the shipped model's size (50 steps, 5 layers, 4 heads) for a 196-frame motion and a
    20-token prompt: steps are grouped only as far as needed to stay under 8 MB; the mean over everything
    is unchanged by the grouping."""
    rng = np.random.default_rng(0)
    tokens = ["[CLS]"] + "a person walks forward then turns around and waves both hands high above the head slowly".split() \
        + ["[SEP]"]
    full = rng.dirichlet(np.ones(len(tokens)), size=(50, 5, 4, LONGEST // 4, 7)).astype(np.float32)
    from salad_viz.synthetic import synthetic_motion

    joints = synthetic_motion("humanml3d", LONGEST)
    page = export_explorer(full, tokens, joints, axes="slhnpw")
    assert page.size_bytes <= MAX_BYTES
    data = _embedded(page)
    groups = data["steps"]["groups"]
    assert groups[0][0] == 0 and groups[-1][1] == 49 and sum(data["steps"]["weights"]) == 50
    att = np.asarray(data["panels"][0]["att"], dtype=np.float64).reshape(data["panels"][0]["shape"]) * data["scale"]
    weights = np.asarray(data["steps"]["weights"], dtype=np.float64)
    mean = np.tensordot(weights / weights.sum(), att, axes=(0, 1)).mean(axis=1)      # (words, P, N')
    ref = full.astype(np.float64).mean(axis=(0, 1, 2))                                 # (N', P, W)
    word = [w["text"] for w in data["panels"][0]["words"]].index("turns")
    np.testing.assert_allclose(mean[word], ref[..., tokens.index("turns")].T, atol=data["scale"])
    small = export_explorer(full, tokens, joints, axes="slhnpw", step_bins=10)
    assert len(_embedded(small)["steps"]["groups"]) == 10 and small.size_bytes < page.size_bytes
    with pytest.raises(ValueError, match="max_bytes"):
        export_explorer(full, tokens, joints, axes="slhnpw", max_bytes=20_000)


def test_page_is_offline_and_inline_view_is_an_iframe(tiny_full, tmp_path):
    joints, maps = tiny_full
    target = tmp_path / "sub" / "explorer.html"
    page = export_explorer(maps, None, joints, path=target)
    assert target.read_text(encoding="utf-8") == page and page.path == target
    # nothing that could load anything: no URL, no src/href, a policy that forbids every request
    assert not re.search(r"https?://|\bsrc\s*=|\bhref\s*=|<link|@import|url\(", page)
    assert "default-src 'none'" in page
    assert page.count("</script>") == 2
    frame = page._repr_html_()
    assert frame.startswith("<iframe") and 'sandbox="allow-scripts"' in frame and "Trust Notebook" in frame
    assert str(target) in frame
    srcdoc = re.search(r'srcdoc="([^"]*)"', frame).group(1)
    assert html.unescape(srcdoc) == page
    assert len(repr(page)) < 200 and "MB of HTML" in repr(page)


def test_bad_inputs_are_refused(tiny_full):
    joints, maps = tiny_full
    with pytest.raises(ValueError, match="tokens is required"):
        export_explorer(maps.cross_map(0), None, joints)
    with pytest.raises(ValueError, match="not in the prompt"):
        export_explorer(maps, None, joints, words="dances")
    with pytest.raises(ValueError, match="tokens has"):
        export_explorer(maps.cross_map(0), maps.tokens(0)[:-1], joints)
    with pytest.raises(ValueError, match="same steps and layers"):
        export_explorer(maps, None, joints, compare=dict(attention=maps.cross_map(0), tokens=maps.tokens(0), joints=joints))
    with pytest.raises(ValueError, match="unknown keys"):
        export_explorer(maps, None, joints, compare=dict(attention=maps, joints=joints, colour="red"))
    with pytest.raises(ValueError, match="view"):
        export_explorer(maps, None, joints, view="sideways")


def test_edit_words_are_paired(pipe):
    from salad_core.attention import WordSwap

    ed = pipe.edit(PROMPT, TARGET, edits=[WordSwap()], lengths=40, num_steps=4, seed=0,
                   capture_attention=CaptureConfig(mode="full"))
    data = explorer_data(ed.source.attention, None, ed.source.joints[0],
                         compare=dict(attention=ed.edited.attention, joints=ed.edited.joints[0]),
                         words=["walks"], edit="word swap: walks -> runs")
    src, dst = data["panels"]
    assert (src["label"], dst["label"]) == ("source", "edited") and data["edit"] == "word swap: walks -> runs"
    swapped = [w["text"] for w in src["words"]].index("walks")
    assert dst["words"][src["align"][swapped]]["text"] == "runs"
    assert [dst["words"][i]["text"] for i in dst["selected"]] == ["runs"]
    assert src["align"] == list(range(len(src["words"])))


# ------------------------------------------------------------------------------ in Chromium
def _browser_reason() -> str | None:
    from _browser import chromium_path

    if chromium_path() is None:
        return "no Chromium at /usr/bin/chromium (scripts/setup.sh installs Debian's 'chromium'; SALAD_CHROMIUM=PATH)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "the Python package 'playwright' is not installed (bash scripts/setup.sh installs it)"
    return None


BROWSER_REASON = _browser_reason()


@pytest.fixture(scope="module")
def shipped():
    """The shipped weights: a full capture of the longest motion, and a word swap of it (full captures)."""
    from salad_core.attention import WordSwap
    from salad_core.pipeline import SaladPipeline

    pipe = SaladPipeline.from_pretrained()
    out = pipe(PROMPT, lengths=LONGEST, num_steps=50, seed=0, capture_attention=CaptureConfig(mode="full"))
    ed = pipe.edit(PROMPT, TARGET, edits=[WordSwap()], lengths=120, num_steps=20, seed=0,
                   capture_attention=CaptureConfig(mode="full"))
    return out, ed


@pytest.fixture(scope="module")
def chromium():
    from _browser import launch_chromium

    with launch_chromium() as browser:
        yield browser


class OfflinePage:
    """A page of its own context, offline, that refuses (and records) every request not to file: or data:."""

    def __init__(self, browser, size=(1280, 800)):
        self.context = browser.new_context(viewport={"width": size[0], "height": size[1]}, offline=True)
        self.requests: list[str] = []
        self.refused: list[str] = []
        self.errors: list[str] = []

        def route(r):
            if r.request.url.startswith(("file:", "data:", "about:")):
                r.continue_()
            else:
                self.refused.append(r.request.url)
                r.abort()

        self.context.route("**/*", route)
        self.page = self.context.new_page()
        self.page.on("request", lambda req: self.requests.append(req.url))
        self.page.on("pageerror", lambda exc: self.errors.append(str(exc)))

    def open(self, path: Path):
        self.page.goto(path.resolve().as_uri())
        self.page.wait_for_function("() => window.saladExplorer !== undefined", timeout=30_000)
        return self.page

    def shot(self, label: str) -> None:
        folder = os.environ.get("SALAD_BROWSER_SHOTS")
        if folder:
            Path(folder).mkdir(parents=True, exist_ok=True)
            self.page.screenshot(path=str(Path(folder) / f"explorer_html_{label}.png"), full_page=True)

    def fetched(self) -> list[str]:
        """What the page asked for beyond its own file."""
        return [u for u in self.requests if not u.startswith(("file:", "data:", "about:"))] + self.refused

    def close(self) -> None:
        self.context.close()


def _state(root) -> dict:
    return root.evaluate("""() => { const ex = window.saladExplorer;
        return {frame: ex.state.frame, playing: ex.state.playing, drawn: ex.panels.map(p => p.drawn),
                maps: ex.panels.map((p, i) => ex.currentMap(i)), scale: ex.state.scale,
                heat: ex.panels.map(p => p.heatDrawn)}; }""")


def _word(maps, word: str) -> int:
    return maps.words(0).index(word)


@pytest.mark.browser
@pytest.mark.slow
@pytest.mark.skipif(BROWSER_REASON is not None, reason=str(BROWSER_REASON))
def test_page_plays_scrubs_and_follows_the_words_offline(shipped, chromium, tmp_path):
    out, _ = shipped
    maps = out.attention
    path = tmp_path / "explorer.html"
    page_text = export_explorer(maps, None, out.joints[0], path=path, model="SALAD (shipped weights)")
    assert page_text.size_bytes <= MAX_BYTES, f"{page_text.size_bytes / 1e6:.2f} MB"
    tab = OfflinePage(chromium)
    try:
        root = tab.open(path)
        page = tab.page
        first = _state(root)
        tab.shot("1-open")
        assert first["frame"] == 0 and first["drawn"][0]["words"] == ["jumps"]
        # the numbers the page computes are AttentionMaps' (default view: every step, layer and head)
        unit = root.evaluate("() => window.saladExplorer.data.scale")
        np.testing.assert_allclose(first["maps"][0], maps.word_map(0, "jumps"), atol=unit)
        # it plays: the frame counter advances, then stops on pause
        page.locator("button.play").click()
        page.wait_for_function("() => window.saladExplorer.state.frame >= 10", timeout=20_000)
        page.locator("button.play").click()
        paused = _state(root)
        assert not paused["playing"]
        time.sleep(0.3)
        assert _state(root)["frame"] == paused["frame"]
        assert "Play" in page.locator("button.play").inner_text()
        # scrubbing moves the skeleton and the heatmap's cursor
        page.locator("input.scrub").fill("20")
        early = _state(root)
        page.locator("input.scrub").fill("170")
        late = _state(root)
        assert (early["frame"], late["frame"]) == (20, 170)
        assert late["drawn"][0]["frame"] == 170 and late["heat"][0]["column"] == 170 // 4
        moved = np.abs(np.subtract(late["drawn"][0]["joints2d"], early["drawn"][0]["joints2d"])).max()
        assert moved > 5, f"the skeleton moved {moved:.1f} px between frames 20 and 170"
        assert late["heat"][0]["cursorX"] > early["heat"][0]["cursorX"]
        tab.shot("3-late-frame")
        # another word: the heatmap's numbers and the bones' colours change, and are the sum of the two words
        page.locator(f"button.chip[data-panel='0'][data-word='{_word(maps, 'waving')}']").click()
        both = _state(root)
        assert both["drawn"][0]["words"] == ["jumps", "waving"]
        assert not np.allclose(both["maps"][0], late["maps"][0])
        assert both["drawn"][0]["boneColors"] != late["drawn"][0]["boneColors"]
        np.testing.assert_allclose(both["maps"][0], maps.word_map(0, "jumps") + maps.word_map(0, "waving"),
                                   atol=2 * unit)
        column = np.asarray(both["maps"][0])[:, 170 // 4]
        np.testing.assert_allclose(both["drawn"][0]["partValues"], column, rtol=0, atol=1e-12)
        assert both["scale"]["hi"] == pytest.approx(np.max(both["maps"][0]))
        tab.shot("2-another-word")
        # layers and steps: the page's map is AttentionMaps.select(...)'s
        page.locator("button.chip[data-layer='1']").click()
        page.locator("button.chip[data-layer='3']").click()
        root.evaluate("() => window.saladExplorer.setSteps(0, 9)")
        narrowed = _state(root)
        ref = maps.select(steps=(0.0, 0.2), layers=[0, 2, 4])
        np.testing.assert_allclose(narrowed["maps"][0], ref.word_map(0, "jumps") + ref.word_map(0, "waving"),
                                   atol=2 * unit)
        assert "steps 0–9 of 50" in page.locator(".filters .readout").inner_text()
        # deselecting the last word is refused (the map never goes empty)
        page.locator(f"button.chip[data-panel='0'][data-word='{_word(maps, 'waving')}']").click()
        page.locator(f"button.chip[data-panel='0'][data-word='{_word(maps, 'jumps')}']").click()
        assert _state(root)["drawn"][0]["words"] == ["jumps"]
        assert "stays selected" in page.locator(".note").inner_text()
        # the header names the prompt and the model
        header = page.locator("header").inner_text()
        assert PROMPT in header and "SALAD (shipped weights)" in header
        assert not tab.errors, tab.errors
        assert tab.fetched() == [], f"the page fetched {tab.fetched()}"
    finally:
        tab.close()


@pytest.mark.browser
@pytest.mark.slow
@pytest.mark.skipif(BROWSER_REASON is not None, reason=str(BROWSER_REASON))
def test_edit_side_by_side_on_one_scale(shipped, chromium, tmp_path):
    _, ed = shipped
    path = tmp_path / "edit.html"
    export_explorer(ed.source.attention, None, ed.source.joints[0], path=path, edit="word swap: walks -> runs",
                    compare=dict(attention=ed.edited.attention, joints=ed.edited.joints[0], label="edited"),
                    words="walks")
    tab = OfflinePage(chromium, size=(1600, 1000))
    try:
        root = tab.open(path)
        st = _state(root)
        assert st["drawn"][0]["words"] == ["walks"] and st["drawn"][1]["words"] == ["runs"]
        unit = root.evaluate("() => window.saladExplorer.data.scale")
        np.testing.assert_allclose(st["maps"][0], ed.source.attention.word_map(0, "walks"), atol=unit)
        np.testing.assert_allclose(st["maps"][1], ed.edited.attention.word_map(0, "runs"), atol=unit)
        top = max(np.max(st["maps"][0]), np.max(st["maps"][1]))
        assert st["scale"]["hi"] == pytest.approx(top)                  # one colour scale for both motions
        assert st["drawn"][0]["scale"] == st["drawn"][1]["scale"]
        assert "word swap: walks -> runs" in tab.page.locator("header h1").inner_text()
        # a word selected in one prompt selects its counterpart in the other
        tab.page.locator(f"button.chip[data-panel='0'][data-word='{_word(ed.source.attention, 'waving')}']").click()
        st = _state(root)
        assert st["drawn"][1]["words"] == ["runs", "waving"]
        root.evaluate("() => window.saladExplorer.setFrame(60)")
        tab.shot("4-edit")
        assert not tab.errors, tab.errors
        assert tab.fetched() == []
    finally:
        tab.close()


@pytest.mark.browser
@pytest.mark.slow
@pytest.mark.skipif(BROWSER_REASON is not None, reason=str(BROWSER_REASON))
def test_inline_iframe_works(tiny_full, chromium, tmp_path):
    """What Jupyter shows (``_repr_html_``) runs inside its sandboxed iframe."""
    joints, maps = tiny_full
    holder = tmp_path / "notebook_output.html"
    holder.write_text("<!DOCTYPE html><html><body>" + export_explorer(maps, None, joints)._repr_html_() + "</body></html>",
                      encoding="utf-8")
    tab = OfflinePage(chromium)
    try:
        tab.page.goto(holder.resolve().as_uri())
        frame = tab.page.frame_locator("iframe.salad-explorer-html")
        frame.locator("button.play").click()
        inner = [f for f in tab.page.frames if f != tab.page.main_frame][0]
        inner.wait_for_function("() => window.saladExplorer && window.saladExplorer.state.frame >= 5", timeout=20_000)
        assert not tab.errors and tab.fetched() == []
    finally:
        tab.close()


@pytest.mark.browser
@pytest.mark.slow
@pytest.mark.skipif(BROWSER_REASON is not None, reason=str(BROWSER_REASON))
def test_the_offline_harness_sees_a_fetch(chromium, tmp_path):
    """The check ``fetched() == []`` above can fail: a page (without the explorer's policy) that asks the
    network for an image is caught."""
    leaky = tmp_path / "leaky.html"
    leaky.write_text('<!DOCTYPE html><html><body><img src="http://192.0.2.1/x.png"></body></html>', encoding="utf-8")
    tab = OfflinePage(chromium)
    try:
        tab.page.goto(leaky.resolve().as_uri())
        tab.page.wait_for_timeout(500)
        assert tab.fetched() and all("192.0.2.1" in u for u in tab.fetched())
    finally:
        tab.close()


@pytest.mark.browser
@pytest.mark.slow
@pytest.mark.skipif(BROWSER_REASON is not None, reason=str(BROWSER_REASON))
def test_saved_notebook_shows_the_explorer_in_jupyterlab(tiny_full, chromium, tmp_path):
    """A notebook saved with the explorer's output, opened again in JupyterLab, shows the page, which plays,
    and the page's frame asks for nothing. The notebook is signed as JupyterLab signs a notebook it saves
    after running it; an unsigned (untrusted) notebook's HTML is sanitised by JupyterLab, which removes the
    iframe until the user trusts the notebook (the HTML file itself still opens anywhere)."""
    import nbformat
    from nbformat.sign import NotebookNotary

    from _browser import LabServer, unavailable_reason

    if unavailable_reason():
        pytest.skip(unavailable_reason())
    joints, maps = tiny_full
    page = export_explorer(maps, None, joints)
    root = tmp_path / "root"
    root.mkdir()
    cell = {"cell_type": "code", "execution_count": 1, "id": "explorer", "metadata": {}, "source": ["page"],
            "outputs": [{"output_type": "execute_result", "execution_count": 1, "metadata": {},
                         "data": {"text/html": page._repr_html_(), "text/plain": repr(page)}}]}
    nb = nbformat.from_dict({"cells": [cell], "nbformat": 4, "nbformat_minor": 5, "metadata": {
        "kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"}}})
    nbformat.write(nb, root / "saved.ipynb")
    lab = LabServer(root)
    (lab.home / "data").mkdir(parents=True)
    NotebookNotary(data_dir=str(lab.home / "data")).sign(nb)     # the server's notary: its data folder
    with lab:
        context = chromium.new_context(viewport={"width": 1400, "height": 1000})
        try:
            tab = context.new_page()
            inner_requests: list[str] = []
            tab.on("request", lambda req: inner_requests.append(req.url) if req.frame != tab.main_frame else None)
            tab.goto(lab.url("/lab/tree/saved.ipynb?reset"), wait_until="domcontentloaded", timeout=180_000)
            tab.frame_locator("iframe.salad-explorer-html").locator("button.play").click(timeout=60_000)
            inner = [f for f in tab.frames if f != tab.main_frame]
            assert len(inner) == 1
            inner[0].wait_for_function("() => window.saladExplorer.state.frame >= 5", timeout=20_000)
            assert [u for u in inner_requests if not u.startswith(("about:", "data:"))] == []
        finally:
            context.close()
