"""The API's protocol commands: the plan of a session and a protocol checked against a
device (``hapticlab protocol show``, ``protocol validate``)."""

from __future__ import annotations

from pathlib import Path

from ._say import to_stderr
from .devices import session_device

__all__ = ["OVERHEAD_S", "protocol_plan", "validate_protocol"]


#: seconds per trial besides tapping (the operator swaps the block, the participant answers):
#: a rule of thumb for the estimate :func:`protocol_plan` gives; a lab measures its own
OVERHEAD_S = 20.0


def protocol_plan(protocol: str | Path, *, seed: int, participant: str = "P00",
                  row: int | None = None) -> dict:
    """The trials a session of ``protocol`` with this seed runs, in order, without redraws
    (``hapticlab protocol show``; plain data, as its ``--json`` prints it).

    Parameters
    ----------
    protocol : str or path
        A built-in name or a protocol file.
    seed : int
        The session seed.
    participant : str
        Participant id.
    row : int, optional
        Counterbalance row, for Williams-ordered blocks.

    Returns
    -------
    dict
        ``protocol``, ``title``, ``source``, ``sha256``, ``seed``, ``participant``,
        ``phases`` (each its ``name``, ``no_repeat`` and ``trials``: sample or surfaces,
        item key, placement, block; an adaptive phase, whose trials follow the answers,
        ``adaptive``: its ``tracks``, ``parameter``, ``units`` and ``max_trials``, counted at
        that most in the estimate), ``design`` and ``duration_estimate`` (``windows``,
        ``window_s``, ``tapping_s`` [s], ``overhead_per_trial_s`` [s] and ``total_s`` [s]).
    """
    from protocols import SessionEngine, load_protocol

    p = load_protocol(protocol)
    engine = SessionEngine(p, seed, participant, row)
    phases: list[dict] = []
    no_repeat = {ph.name: ph.no_repeat for ph in p.phases}
    adaptive = {ph.name: ph.adaptive for ph in p.phases if ph.adaptive is not None}
    for item, place in zip(engine.plan(), engine.placements(), strict=True):
        if not phases or phases[-1]["name"] != item.phase:
            phases.append({"name": item.phase, "no_repeat": no_repeat[item.phase],
                           "trials": []})
        if item.marker:  # made from the answers: its tracks and its most trials, two windows each
            a = adaptive[item.phase]
            phases[-1]["adaptive"] = {"tracks": [tr.name for tr in a.tracks],
                                      "parameter": a.parameter, "units": a.units,
                                      "max_trials": a.max_total()}
            continue
        trial = {"sample": item.samples[0] if len(item.samples) == 1 else list(item.samples),
                 "item": item.key, "placement": place}
        if item.block is not None:
            trial["block"] = item.block
        phases[-1]["trials"].append(trial)
    most = sum(ph["adaptive"]["max_trials"] for ph in phases if "adaptive" in ph)
    n = sum(len(ph["trials"]) for ph in phases) + most
    windows = sum(len(t["sample"]) if isinstance(t["sample"], list) else 1
                  for ph in phases for t in ph["trials"]) + 2 * most
    tapping = windows * p.window.duration
    return {"protocol": p.name, "title": p.title, "source": p.source, "sha256": p.sha256,
            "seed": seed, "participant": participant, "phases": phases, "design": p.design(),
            "duration_estimate": {"windows": windows, "window_s": p.window.duration,
                                  "tapping_s": tapping, "overhead_per_trial_s": OVERHEAD_S,
                                  "total_s": tapping + n * OVERHEAD_S}}


def validate_protocol(protocol: str | Path, *, device: str | None = None,
                      clear_fault: bool = False) -> dict:
    """Check a protocol file, and with ``device`` its forces, currents and rendering against
    that device (``hapticlab protocol validate``).

    Parameters
    ----------
    protocol : str or path
        A built-in name or a protocol file.
    device : str, optional
        A device spec (``sim``, ``serial:PORT``): opened once, to read what it can render
        and which transient libraries it has.
    clear_fault : bool
        Clear a fault the device latched before (the operator's decision).

    Returns
    -------
    dict
        ``protocol``, ``source``, ``samples``, ``phases``, ``trials`` (the engine's plan,
        without redraws), ``device`` (the spec or None), ``libraries`` (what was found or
        will be built, in words, or ""), ``warnings`` (what the device renders otherwise
        than asked) and ``notes`` (texts left in English).

    Raises
    ------
    ProtocolError
        Naming the file, line and key of the first problem.
    """
    from protocols import SessionEngine, load_protocol
    from protocols.texts import english_note

    info, found, warnings, libraries = None, {}, [], ""
    if device:
        from app.libraries import builds_on_demand, prepare_libraries
        from app.preflight import rendering_notes

        with session_device(device, 0, person=False, clear_fault=clear_fault, lsl=False,
                             say=to_stderr) as dev:
            info = dev.info
            p = load_protocol(protocol, device=info)
            built = builds_on_demand(info)
            found = prepare_libraries(p, dev, device, build=False, ref=str(protocol)) \
                if not built else {}
        if built and any(s.scene.kind == "library" for s in p.samples.values()):
            libraries = "matched samples: a missing library is built on first use (simulated)"
        elif found:
            libraries = f"libraries found for {', '.join(sorted(found))}"
        warnings = list(rendering_notes(p, info))
    else:
        p = load_protocol(protocol)
    # the engine's own plan (any seed and counterbalance row plan as many trials)
    williams = any(ph.block_order == "williams" for ph in p.phases)
    # (an adaptive phase's at its most: its tracks' caps and catch trials)
    trials = SessionEngine(p, 0, "validate", 0 if williams else None).max_trials()
    note = english_note(p)
    return {"protocol": p.name, "source": p.source, "samples": len(p.samples),
            "phases": len(p.phases), "trials": trials,
            "adaptive": any(ph.adaptive is not None for ph in p.phases), "device": device,
            "libraries": libraries, "warnings": warnings, "notes": [note] if note else []}
