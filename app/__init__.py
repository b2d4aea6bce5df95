"""The experiment application: command line, runner, screens, console, audio, recorder.

The only package that imports PsychoPy (lazily, in the screen module).
"""

__all__: list[str] = []
