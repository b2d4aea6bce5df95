"""Audio cues through PsychoPy's sound: masking white noise, the spoken "tap", a low tone.

Imported only when a session uses audio; PsychoPy stays out of every other package.
"""

from __future__ import annotations

from importlib import resources

import numpy as np

__all__ = ["Audio", "AudioUnavailable"]


class AudioUnavailable(RuntimeError):
    """No sound library or no output device."""


def _outputs() -> int | None:
    """Output devices PortAudio lists (None when it cannot be asked)."""
    try:
        import sounddevice

        return sum(d["max_output_channels"] > 0 for d in sounddevice.query_devices())
    except Exception:  # noqa: BLE001 — no PortAudio: PsychoPy's own error will say
        return None


class Audio:
    """Masking noise (looped), the "tap" cue and the saturation tone, with set volumes."""

    def __init__(self, noise_volume: float = 0.3, cue_volume: float = 0.8,
                 tone_volume: float = 0.6, rate: int = 44_100):
        try:
            from psychopy import prefs

            prefs.hardware["audioLib"] = ["sounddevice", "ptb"]
            from psychopy import sound
        except Exception as exc:  # ImportError, or a backend that fails to load
            raise AudioUnavailable(f"PsychoPy sound is not available: {exc}") from None
        outputs = _outputs()
        if outputs == 0:
            raise AudioUnavailable("no audio output device: the sound system (PortAudio) lists "
                                   "none — is a sound card connected and the sound server "
                                   "(PulseAudio, PipeWire) running for this user? Or run "
                                   "with --no-audio")
        rng = np.random.default_rng(0)
        try:
            self._noise = sound.Sound(rng.uniform(-1, 1, rate * 2) * noise_volume, loops=-1,
                                      sampleRate=rate, stereo=True)
            self._tone = sound.Sound(value=110, secs=0.4, volume=tone_volume, sampleRate=rate)
            wav = resources.files("app").joinpath("data/tap.wav")
            self._cue = sound.Sound(str(wav), volume=cue_volume)
            self._noise.play()
        except Exception as exc:
            detail = f"(PsychoPy said: {type(exc).__name__}: {exc})"
            if outputs is None:
                raise AudioUnavailable(
                    "no audio output could be opened, and the sound system (PortAudio) could "
                    "not be asked which output devices exist — is PortAudio installed and a "
                    "sound server (PulseAudio, PipeWire) running for this user? Or run with "
                    f"--no-audio {detail}") from None
            raise AudioUnavailable(
                f"the sound system lists {outputs} output device(s) but none could be opened "
                "— check the default output device in the system's sound settings, or run "
                f"with --no-audio {detail}") from None

    def tap_cue(self) -> None:
        self._cue.play()

    def low_tone(self) -> None:
        self._tone.play()

    def close(self) -> None:
        for s in (self._noise, self._cue, self._tone):
            try:
                s.stop()
            except Exception:  # a device that went away
                pass
