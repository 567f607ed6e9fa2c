"""PyInstaller runtime hook of winder: make the bundle self-contained before ``engine.cli`` loads.

OpenCASCADE (OCP, cadquery).  ``CASROOT`` always names ``<bundle>/opencascade``, so a
``CASROOT``/``CSF_*`` set on the host for another OCCT version is never mixed with the bundled
libraries.  The ``CSF_*`` resource variables are set only for the files the bundle really holds:
the pip ``cadquery-ocp`` wheels compile OCCT's resources in (nothing to ship, OCCT's built-in
defaults apply); a conda OCCT ships ``share/opencascade/resources``, which ``winder.spec`` then
bundles as ``opencascade/resources``.

Fontconfig and locale (Linux): the bundled library reads the host's ``/etc/fonts/fonts.conf``;
with no locale set at all (``env -i``), ``C.UTF-8`` is used (Qt would otherwise warn on stderr).
DLLs (Windows): casadi and OCP load companion DLLs from their own package folders.
"""

import os
import sys


def _set_occt_environment(bundle: str) -> None:
    casroot = os.path.join(bundle, "opencascade")
    os.environ["CASROOT"] = casroot
    res = os.path.join(casroot, "resources")
    wanted = {
        "CSF_OCCTResourcePath": res,
        "CSF_ShadersDirectory": os.path.join(res, "Shaders"),
        "CSF_UnitsLexicon": os.path.join(res, "UnitsAPI", "Lexi_Expr.dat"),
        "CSF_UnitsDefinition": os.path.join(res, "UnitsAPI", "Units.dat"),
        "CSF_SHMessage": os.path.join(res, "SHMessage"),
        "CSF_XSMessage": os.path.join(res, "XSMessage"),
        "CSF_TObjMessage": os.path.join(res, "TObj"),
        "CSF_StandardDefaults": os.path.join(res, "StdResource"),
        "CSF_PluginDefaults": os.path.join(res, "StdResource"),
        "CSF_XCAFDefaults": os.path.join(res, "StdResource"),
        "CSF_StandardLiteDefaults": os.path.join(res, "StdResource"),
        "CSF_STEPDefaults": os.path.join(res, "XSTEPResource"),
        "CSF_IGESDefaults": os.path.join(res, "XSTEPResource"),
        "CSF_XmlOcafResource": os.path.join(res, "XmlOcafResource"),
        "CSF_MDTVTexturesDirectory": os.path.join(res, "Textures"),
    }
    for name, path in wanted.items():
        if os.path.exists(path):
            os.environ[name] = path
        else:
            os.environ.pop(name, None)  # a host value would point at another OCCT


def _set_fontconfig() -> None:
    # The bundled libfontconfig may have been built with another sysconfdir than the host's.
    if sys.platform.startswith("linux") and "FONTCONFIG_FILE" not in os.environ:
        if os.path.isfile("/etc/fonts/fonts.conf"):
            os.environ["FONTCONFIG_FILE"] = "/etc/fonts/fonts.conf"
            os.environ.setdefault("FONTCONFIG_PATH", "/etc/fonts")
    if sys.platform.startswith("linux") and not any(os.environ.get(v) for v in ("LC_ALL", "LC_CTYPE", "LANG")):
        os.environ["LC_CTYPE"] = "C.UTF-8"


def _add_dll_directories(bundle: str) -> None:
    if sys.platform == "win32":
        for pkg in ("casadi", "OCP", "vtkmodules"):
            d = os.path.join(bundle, pkg)
            if os.path.isdir(d):
                os.add_dll_directory(d)


_set_occt_environment(getattr(sys, "_MEIPASS", os.path.dirname(os.path.abspath(sys.executable))))
_set_fontconfig()
_add_dll_directories(getattr(sys, "_MEIPASS", ""))
