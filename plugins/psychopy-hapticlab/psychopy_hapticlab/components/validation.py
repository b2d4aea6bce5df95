"""The alert Builder shows for a hapticlab parameter it cannot use.

PsychoPy's alerts are numbered entries of its catalogue (``psychopy.alerts.catalog``); a
plugin cannot ship a catalogue file, so the entry is added when a component is made, under
a code of the Builder-experiments range (4xxx) that PsychoPy does not use. Builder's alerts
panel (Runner) then shows it whenever the experiment is checked: the component's name and
hapticlab's own words for what is wrong.
"""

from __future__ import annotations

__all__ = ["ALERT", "register_alert"]

#: the alert's code
ALERT = 4856

_ENTRY = {
    "code": ALERT,
    "cat": "Components",
    "msg": "hapticlab component {name}: {problem}",
    "label": "A hapticlab parameter cannot be used",
    "url": "https://psychopy.org/alerts/4856.html",
    "synopsis": "A Haptic contact or Haptic device check parameter is outside what hapticlab "
                "accepts (the message names the field, the value and what is allowed).",
    "solutions": "Correct the parameter in the component's dialog.",
}


def register_alert() -> None:
    """Add the entry to PsychoPy's alert catalogue once.

    Raises
    ------
    RuntimeError
        PsychoPy already has an alert of that code for something else.
    """
    from psychopy.alerts import catalog

    have = catalog.alert.get(ALERT)
    if have is None:
        catalog.alert[ALERT] = dict(_ENTRY)
    elif have.get("label") != _ENTRY["label"]:
        raise RuntimeError(f"PsychoPy's alert {ALERT} is {have.get('label')!r}: "
                           "psychopy-hapticlab needs another code")
