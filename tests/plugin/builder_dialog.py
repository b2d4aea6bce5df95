"""Open PsychoPy Builder (psychopy-app) on an experiment and save screenshots of the Haptic
contact component's dialog and of the Device Manager (a test helper, run under Xvfb).

usage: builder_dialog.py IN.psyexp COMPONENT OUT-FOLDER

Writes builder-haptic-contact.png (the dialog on its Scene page) and
builder-device-manager.png into OUT-FOLDER.
"""

import sys
from pathlib import Path


def grab(window, path: Path) -> None:
    """The window's pixels as the X server shows them."""
    from PIL import ImageGrab

    x, y = window.GetScreenPosition()
    w, h = window.GetSize()
    ImageGrab.grab(bbox=(x, y, x + w, y + h)).save(path)


def main(psyexp: str, component: str, out: str) -> int:
    import wx
    from psychopy import plugins

    plugins.activatePlugins()
    import psychopy_app
    from psychopy_app.builder.dialogs import DlgComponentProperties

    psychopy_app.startApp(showSplash=False, testMode=True, startView="builder",
                          startFiles=[psyexp])
    app = psychopy_app.getAppInstance()
    frames = app.builder if isinstance(app.builder, list) else [app.builder]
    frame = frames[-1]
    exp = frame.exp
    comp = next(c for rt in exp.routines.values() for c in rt
                if getattr(c, "params", {}).get("name") == component)
    folder = Path(out)
    shots = []

    def contact_dialog():
        dlg = DlgComponentProperties(frame, comp, exp, editing=True, testing=True,
                                     openToPage="Scene")
        dlg.SetSize((760, 900))
        shots.append(dlg)
        wx.CallLater(1500, lambda: (grab(dlg, folder / "builder-haptic-contact.png"),
                                    device_manager()))

    def device_manager():
        shots[-1].Destroy()
        from psychopy_app.deviceManager.dialog import DeviceManagerDlg

        dlg = DeviceManagerDlg(frame)
        dlg.Show()
        dlg.SetSize((900, 600))
        wx.CallLater(1500, lambda: (grab(dlg, folder / "builder-device-manager.png"),
                                    app.ExitMainLoop()))

    wx.CallLater(2000, contact_dialog)
    app.MainLoop()
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
