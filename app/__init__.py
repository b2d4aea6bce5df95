"""The experiment application: command line, runner, screens, console, audio, recorder.

The only package that imports PsychoPy (lazily, in the screen module).
"""

__all__ = ["__version__"]

#: the application's version (pyproject.toml's; recorded in every session.json)
__version__ = "0.1.0"
