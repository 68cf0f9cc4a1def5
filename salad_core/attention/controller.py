"""The edit controller: one batched forward per step serves the source, the probe and the edited
sample (SALAD supplement B, Algorithm 1, in Prompt-to-Prompt's batched form).

Algorithm 1 runs, per step, the source ``Denoise(z_t, t, c)`` (maps ``M``), a probe
``Denoise(z*_t, t, c*)`` (the target's own maps ``M*``, its latent discarded) and the edited step
``Denoise(z*_t, t, c*){M <- M_hat}``. Because every row of a batched forward is computed
independently, the source's ``M`` and the probe's ``M*`` at layer ``l`` are available at the
moment the edited row reaches layer ``l``; no map is stored across steps. Rows of the forward
batch (:class:`RowLayout`)::

    unconditional:  source (B) | edited (B)        -- never edited (as the official code)
    conditional:    source (B) | probe (B)? | edited (B)

Shared work is computed once: the probe has no unconditional row (its latent update is discarded
and the edited sample's unconditional row sees the same latent and null text), the probe is
skipped at steps where the edit does not read the target's own maps (re-weighting and mirroring
never do; word swap only after its window when a modifier follows), and while the two latents
are still equal (step 0) the edited sample's unconditional row is the source's.

By default (``probe=False``) even the probe is folded into the edited row: where ``M*`` is
needed it is read from the edited row's own attention at the same layer of the same forward,
which is how Prompt-to-Prompt's implementation obtains it. ``probe=True`` runs the separate probe
row of Algorithm 1 (line 7), as the official code does.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import torch

from salad_core.models.attention import SiteInfo

from .capture import AttentionMaps, AttentionStore, CaptureConfig, TokenInfo, as_capture_config
from .edits import EditKernel, EditSpec, validate_edits

__all__ = ["RowLayout", "EditController"]


@dataclass(frozen=True)
class RowLayout:
    """Rows of one step's forward batch for ``batch`` source/target pairs.

    ``cfg``: unconditional rows exist; ``probe``: the probe rows exist; ``share_uncond``: the
    edited sample's unconditional rows are omitted (reuse the source's: equal latents);
    ``edited``: the edited rows exist (False for plain reconstruction).
    """

    batch: int
    cfg: bool
    probe: bool
    share_uncond: bool = False
    edited: bool = True

    def _range(self, start: int) -> torch.Tensor:
        return torch.arange(start, start + self.batch)

    @property
    def num_uncond(self) -> int:
        if not self.cfg:
            return 0
        return self.batch * (1 if self.share_uncond or not self.edited else 2)

    @property
    def source_uncond(self) -> torch.Tensor:
        return self._range(0)

    @property
    def edited_uncond(self) -> torch.Tensor:
        return self._range(0 if self.share_uncond else self.batch)

    @property
    def source_cond(self) -> torch.Tensor:
        return self._range(self.num_uncond)

    @property
    def probe_cond(self) -> torch.Tensor:
        if not self.probe:
            raise RuntimeError("this step has no probe rows")
        return self._range(self.num_uncond + self.batch)

    @property
    def edited_cond(self) -> torch.Tensor:
        return self._range(self.num_uncond + self.batch * (2 if self.probe else 1))

    @property
    def rows(self) -> int:
        """Rows of the forward batch."""
        cond = self.batch * (1 + int(self.edited) + int(self.probe))
        return self.num_uncond + cond


def _kernel_of_kind(kernel: EditKernel | dict[str, EditKernel], kind: str) -> EditKernel:
    """An injection's kernel for one attention kind: specs whose kernels differ by kind
    (:class:`~salad_core.attention.edits.MirrorSelfAttention`) bind a dict of them."""
    return kernel[kind] if isinstance(kernel, dict) else kernel


class EditController:
    """Builds ``M_hat`` at every cross site (and injects self-attention) for the edited rows.

    Each spec's kernel (:meth:`EditSpec.bind <salad_core.attention.edits.EditSpec.bind>`) does the
    editing; the controller only plans the rows of each step and composes the active kernels. It
    records attention on request (:meth:`record_attention`, then :meth:`maps`).

    Parameters
    ----------
    edits : sequence of EditSpec
        Validated with :func:`~salad_core.attention.edits.validate_edits`.
    source, target : TokenInfo
        Tokens of the ``B`` source and target prompts.
    width : int
        ``W`` of the forward's token axis (the wider of the two prompts' padded widths).
    cfg : bool
        Classifier-free guidance (unconditional rows present).
    edited : bool
        False: only the source rows exist (reconstruction of an inverted motion).
    probe : bool
        Where the target's own maps ``M*`` come from when an edit reads them (prompt refinement's
        inserted tokens; the base map after a word swap's window when a modifier follows).
        False (default): from the edited row itself, in the same forward, at the same layer, as
        Prompt-to-Prompt's implementation does; 4 rows per step. True: from a separate probe row
        run without any modification, exactly as Algorithm 1 (line 7) and the official code;
        5 rows at the steps that need it.
    """

    def __init__(self, edits: Sequence[EditSpec], source: TokenInfo, target: TokenInfo, width: int,
                 cfg: bool, edited: bool = True, probe: bool = False) -> None:
        self.edits = validate_edits(edits)
        self.use_probe = bool(probe)
        if len(source) != len(target):
            raise ValueError(f"got {len(source)} source prompts and {len(target)} target prompts; pair them one to one")
        self.source, self.target, self.width, self.cfg, self.edited = source, target, int(width), cfg, edited
        self.batch = len(source)
        self.same_prompt = [source.tokens[b] == target.tokens[b] for b in range(self.batch)]
        repl = [i for i, e in enumerate(self.edits) if e.role == "replace"]
        self._repl_index = repl[0] if repl else None
        self.replacement: EditSpec | None = self.edits[repl[0]] if repl else None
        self.modifiers = [e for e in self.edits if e.role == "modify"]
        self.injections = [e for e in self.edits if e.role == "inject"]
        if self.replacement is None and self.modifiers and not all(self.same_prompt):
            bad = [b for b in range(self.batch) if not self.same_prompt[b]]
            raise ValueError(
                f"pairs {bad} have a target prompt different from the source (e.g. {target.prompts[bad[0]]!r} vs "
                f"{source.prompts[bad[0]]!r}) but no WordSwap or Refine: re-weighting, mirroring, erasing and shifting "
                "modulate the source's own maps (paper supplement B), so give the same prompt or add Refine() first")
        # every spec looks up what it needs in the prompts once; the modifiers edit the maps of the
        # target after a replacement, else the source's own
        maps_of = target if self.replacement is not None else source
        self._kernels: list[EditKernel] = [e.bind(source, target, self.width, maps_of=maps_of) for e in self.edits]
        self.layout = RowLayout(self.batch, cfg, probe=False, edited=edited)
        self.stores: dict[str, AttentionStore] = {}
        self._fraction = 0.0
        self._cross_active = False
        self._repl_active = False
        self._mods_active: list[int] = []
        self._inject_active: dict[str, EditKernel] = {}
        self._reads_own = False
        self.probe_steps = 0
        self.rows_total = 0

    # -------------------------------------------------------------- capture
    def record_attention(self, config: bool | CaptureConfig | dict, lengths: Sequence[int], *, num_layers: int,
                         num_heads: int, unit_length: int | None = None) -> None:
        """Record the source rows' maps ``M`` (store ``"source"``) and, when editing, the maps the
        edited rows used (``"edited"``: ``M_hat`` where the edit replaced them); read them with
        :meth:`maps` after the loop.

        Parameters
        ----------
        config : True, CaptureConfig or dict
        lengths : sequence of int
            Motion lengths in frames.
        num_layers, num_heads : int
            Of the denoiser.
        unit_length : int, optional
            Frames per latent frame (default: the skeletons' 4).
        """
        cap = as_capture_config(config)
        self.stores = {"source": AttentionStore(self.source, lengths, cap, num_layers, num_heads, unit_length,
                                                rows=lambda info: self.layout.source_cond)}
        if self.edited:
            self.stores["edited"] = AttentionStore(self.target, lengths, cap, num_layers, num_heads, unit_length,
                                                   rows=lambda info: self.layout.edited_cond)

    def maps(self, branch: str) -> AttentionMaps | None:
        """The maps recorded for ``branch`` (``"source"`` or ``"edited"``), None without capture."""
        if branch not in ("source", "edited"):
            raise ValueError(f"branch must be 'source' or 'edited', got {branch!r}")
        store = self.stores.get(branch)
        return None if store is None else store.result()

    # ----------------------------------------------------------------- steps
    def needs_probe(self, fraction: float) -> bool:
        """Whether the edit reads the target's own maps ``M*`` at this step fraction (from the
        probe row, or from the edited row itself when ``probe=False``)."""
        repl = self.replacement
        mods = any(m.active(fraction) for m in self.modifiers)
        if repl is None:
            return False
        if repl.active(fraction):
            return repl.reads_target               # word swap copies the source only
        # after the replacement's window the base is M*; unmodified, it is the edited row's own
        return mods

    def on_step(self, info: Any, latents_equal: bool = False) -> RowLayout:
        """Plan the step (call before building the forward batch); returns its row layout."""
        p = info.index / info.num_steps
        self._fraction = p
        self._repl_active = self.replacement is not None and self.replacement.active(p)
        self._mods_active = [i for i, e in enumerate(self.edits) if e.role == "modify" and e.active(p)]
        self._cross_active = self.edited and (self._repl_active or bool(self._mods_active))
        self._inject_active = {k: _kernel_of_kind(self._kernels[i], k) for i, e in enumerate(self.edits)
                               if e.role == "inject" and self.edited and e.active(p) for k in e.site_kinds}
        reads_own = self.edited and self.needs_probe(p)
        probe = reads_own and self.use_probe
        self._reads_own = reads_own and not probe
        self.layout = RowLayout(self.batch, self.cfg, probe, share_uncond=self.edited and latents_equal,
                                edited=self.edited)
        self.probe_steps += int(probe)
        self.rows_total += self.layout.rows
        for store in self.stores.values():
            store.on_step(info)
        return self.layout

    @property
    def site_kinds(self) -> set[str]:
        """Attention kinds whose sites the controller edits, injects into or records."""
        kinds = {"cross"} | {k for e in self.injections for k in e.site_kinds}
        for store in self.stores.values():
            kinds |= set(store.kinds)
        return kinds

    @property
    def modifies(self) -> bool:
        """Whether the current step changes any attention of the edited rows."""
        return self._cross_active or bool(self._inject_active)

    # --------------------------------------------------------- SiteHook API
    def rows(self, site: SiteInfo) -> torch.Tensor | None:
        lay = self.layout
        need: list[torch.Tensor] = []
        if site.kind == "cross" and self._cross_active:
            need.append(lay.source_cond)
            if lay.probe:
                need.append(lay.probe_cond)
            elif self._reads_own:
                need.append(lay.edited_cond)
        if site.kind in self._inject_active:
            need.append(lay.source_cond)
        src = self.stores.get("source")
        if src is not None and src.wants(site):
            need.append(lay.source_cond)
        ed = self.stores.get("edited")
        if ed is not None and ed.wants(site) and lay.edited:
            need.append(lay.edited_cond)
        if not need:
            return None
        return torch.unique(torch.cat(need))

    def process(self, site: SiteInfo, rows: torch.Tensor, probs: torch.Tensor):
        lay = self.layout
        pos = {int(r): i for i, r in enumerate(rows.tolist())}

        def pick(which: torch.Tensor) -> torch.Tensor:
            return probs[torch.tensor([pos[int(r)] for r in which.tolist()])]

        new: torch.Tensor | None = None
        if site.kind == "cross" and self._cross_active:
            src = pick(lay.source_cond)
            own = pick(lay.probe_cond) if lay.probe else (pick(lay.edited_cond) if self._reads_own else None)
            new = self.edit_cross(src, own)
        elif site.kind in self._inject_active:
            new = self._inject_active[site.kind](pick(lay.source_cond), None)   # source self-attention
        src_store, ed_store = self.stores.get("source"), self.stores.get("edited")
        if src_store is not None and src_store.wants(site):
            src_store.record(site, pick(lay.source_cond))
        if ed_store is not None and ed_store.wants(site) and lay.edited:
            ed_store.record(site, new if new is not None else pick(lay.edited_cond))
        if new is None:
            return None
        return lay.edited_cond, new

    # ---------------------------------------------------------- the edit
    def edit_cross(self, source: torch.Tensor, target: torch.Tensor | None) -> torch.Tensor:
        """``M_hat`` ``(B, H, N', P, W)`` from the source maps and (if probed) the target's own.

        The composition of the active specs at the current step (see :mod:`.edits`): the
        replacement's kernel builds the base in its window (the target's own maps after it; the
        source's own without a replacement), then each active modifier's kernel, in order.
        """
        repl = self.replacement
        if repl is None:
            out = source                                          # paper: modulate M_t
        elif self._repl_active:
            out = self._kernels[self._repl_index](source, target)
        else:
            if target is None:
                raise RuntimeError("the target's own maps are needed but the step has no probe")
            out = target
        for i in self._mods_active:
            out = self._kernels[i](out, None)
        return out
