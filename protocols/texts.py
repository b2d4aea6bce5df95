"""What the participant reads: the default texts, in English, and how a protocol changes them.

A protocol's ``[texts]`` table replaces any of :data:`DEFAULT_TEXTS` (a lab translates or
rewords them without touching code; ``language`` says which language they are in), and
``[texts.instructions]`` gives a phase, by name, its own instructions. Placeholders in
braces are filled in by the screen: ``{min}``, ``{max}`` (the scale), ``{keys}`` (the
surface keys), ``{names}`` (the answer keys and names), ``{list}`` (surfaces tapped so far),
``{i}`` (the surface being named), ``{block}`` (the real block to tap).

The keys these texts name are the keys the screen uses: SPACE begins a phase, ENTER ends
familiarization and confirms a typed or slider rating, R asks for the real block again,
number keys choose surfaces (also during a surface's window, which then ends) and name
them (and, where a phase has several real blocks, the block to tap again), N starts
naming.
"""

from __future__ import annotations

from .kinds import phase_kind
from .responses import response, responses

__all__ = ["DEFAULT_TEXTS", "resolve_texts", "left_in_english", "english_note"]

DEFAULT_TEXTS: dict[str, str] = {
    "language": "en",
    "tap": "Tap",
    "done_hint": "press ENTER when you are done",
    "wait": "Please wait",
    "wait_detail": "The experimenter is preparing the next sample.",
    "reference_offer": "Press R to tap the real block again.",
    "reference_requested": "The experimenter is placing the real block.",
    "reference_which": "Which real block would you like to tap again?",
    "reference_which_keys": "{names}      (ESC: none)",
    "saturated": "That tap was too hard for the device: this sample comes back later.",
    "saturated_last": "That tap was too hard for the device. Please tap more gently.",
    "surface": "Surface {i}",
    "reference": "Tap the real block",
    "reference_detail": "Compare the next samples with this one: {block}.",
    "choose": "Choose a surface: {keys}",
    "tapped": "tapped: {list}",
    "switch_hint": "another surface: {keys}",
    "pair": "sample {i} of 2",
    "paused": "Paused",
    "paused_detail": "The experimenter will continue shortly.",
    "debrief": "What made a sample feel real or not?",
    "debrief_hint": "Type, then press ENTER.",
    "thanks": "Thank you. The session is over.",
    # each response's own texts (protocols.responses)
    **{k: v for r in map(response, responses()) for k, v in r.texts.items()},
}


def resolve_texts(overrides: dict[str, str], instructions: dict[str, str]) -> dict:
    """Defaults with a protocol's changes: ``{key: text, ..., "instructions": {phase: text}}``."""
    out = {**DEFAULT_TEXTS, **overrides}
    out["instructions"] = dict(instructions)
    return out


#: which screens show a text: every protocol, or only one with a phase whose kind makes its
#: items so ("pairs"), runs its windows so ("until_done", "surfaces") or asks for that
#: response (its name: a response's texts are its own, protocols.responses),
#: rating entry ("keys", "typed", "slider"), saturated trials redrawn ("redraw") or real
#: blocks ("references"; "several": a surfaces phase offering more than one, which the
#: participant chooses between); texts of placeholders alone need no translation
_SHOWN_WHEN = {
    "tap": "all", "wait": "all", "wait_detail": "all", "saturated": "redraw",
    "saturated_last": "redraw", "paused": "all",
    "paused_detail": "all", "debrief": "all", "debrief_hint": "all", "thanks": "all",
    "done_hint": "until_done", "reference_offer": "references",
    "reference_requested": "references",
    "reference": "references", "reference_detail": "references",
    "reference_which": "several", "reference_which_keys": "several",
    "surface": "surfaces", "choose": "surfaces", "tapped": "surfaces",
    "switch_hint": "surfaces", "pair": "two_windows",
    # each response's own texts: shown when a phase asks for it, or as it says
    **{k: r.shown_when.get(k, r.name) for r in map(response, responses()) for k in r.texts},
}


def left_in_english(protocol) -> list[str]:
    """The texts a participant of ``protocol`` will read in English although the protocol
    says it is in another language: each a ``[texts]`` key, or ``instructions.<phase>``.

    Empty for an English protocol. A lab that translated a protocol before a text was added
    to hapticlab learns here which ones to add (``protocol validate`` lists them).
    """
    import re

    texts = protocol.texts
    if re.split(r"[-_]", texts.get("language", "en"))[0].lower() == "en":
        return []
    kinds = [phase_kind(ph.kind) for ph in protocol.phases]
    offered = [ph for ph in protocol.phases if ph.references != "none"]
    several = any(phase_kind(ph.kind).surfaces and len(
        {protocol.samples[s].reference for s in ph.samples} - {None}) > 1 for ph in offered)
    shown = {"all", *(k.items for k in kinds), *(k.windows for k in kinds),
             # "sample 1 of 2": a trial's two windows, a pair's or an adaptive trial's
             *(("two_windows",) if any(
                 phase_kind(ph.kind).items == "pairs" or (
                     ph.adaptive is not None and ph.adaptive.presentation == "intervals")
                 for ph in protocol.phases) else ()),
             # an adaptive phase presented as two surfaces shows the surfaces' texts
             *(("surfaces",) if any(ph.adaptive is not None and
                                    ph.adaptive.presentation == "surfaces"
                                    for ph in protocol.phases) else ()),
             *(k.response for k in kinds),
             *(("references",) if offered and any(
                 s.reference for s in protocol.samples.values()) else ()),
             *(("several",) if several else ()),
             *((protocol.rating.entry_mode,) if protocol.rating is not None else ()),
             *(("redraw",) if protocol.saturation.action == "redraw" else ())}
    out = [k for k, when in _SHOWN_WHEN.items()
           if when in shown and texts.get(k) == DEFAULT_TEXTS[k]]
    return out + [f"instructions.{ph.name}" for ph in protocol.phases
                  if ph.name not in texts.get("instructions", {})]


def english_note(protocol) -> str:
    """One sentence on :func:`left_in_english`, or "" when nothing is."""
    english = left_in_english(protocol)
    if not english:
        return ""
    n = len(english)
    return (f"the protocol is in language '{protocol.texts['language']}', but its participants "
            f"will read {n} text{'' if n == 1 else 's'} in English (not in its [texts]): "
            f"{', '.join(english)}")
