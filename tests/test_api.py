import subprocess
import sys

import transync


def test_every_public_name_resolves():
    for name in transync.__all__:
        assert getattr(transync, name) is not None, name
    assert set(transync.__all__) <= set(dir(transync))


def test_import_is_light():
    code = ("import sys, transync; "
            "print(any(m in sys.modules for m in ('cv2', 'skimage', 'matplotlib', 'sklearn')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "False"


def test_unknown_attribute():
    import pytest

    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        transync.nope  # noqa: B018
