# SPDX-License-Identifier: GPL-3.0-or-later
"""Issue 59: every public name of the package is documented (the site's API reference is made from
these docstrings by autodoc), and the mode entry points state their units."""
import inspect

import physreg


def prose(obj, name):
    """The docstring without pybind11's generated signature lines ("name(arg: type, ...) -> type"
    and "Overloaded function."): what a person wrote."""
    lines = [l for l in (getattr(obj, "__doc__", None) or "").splitlines()
             if not l.strip().startswith(name + "(") and not l.strip().startswith(f"{name}(") and l.strip() != "Overloaded function."
             and not (l.strip()[:2].rstrip(".").isdigit() and f"{name}(" in l)]
    return "\n".join(lines).strip()


def public_names():
    return [n for n in dir(physreg) if not n.startswith("_") and not inspect.ismodule(getattr(physreg, n))]


def test_every_public_name_has_a_docstring():
    undocumented = [n for n in public_names() if not prose(getattr(physreg, n), n)]
    assert undocumented == [], undocumented


def test_the_public_classes_document_their_methods():
    missing = []
    for n in public_names():
        obj = getattr(physreg, n)
        if not inspect.isclass(obj) or issubclass(obj, BaseException):
            continue
        for m, member in vars(obj).items():
            if m.startswith("_") or not callable(member):
                continue
            if not prose(member, m):
                missing.append(f"{n}.{m}")
    assert missing == [], missing


def test_the_mode_entry_points_say_their_units():
    for f in (physreg.register_surface, physreg.register_images, physreg.register_compression, physreg.register_partial_surface,
              physreg.register_image_pair, physreg.predict_compression):
        text = f.__doc__ or ""
        assert "mm" in text or "settings_spec" in text or "physreg register-" in text, f.__name__
