"""A realtime stylistic walk synthesizer: HSMM style models, streaming MLPG, live control."""

import os as _os

__version__ = "0.1.0"


def _numba_cache_dir() -> str:
    """Where numba keeps the compiled kernels: a cache folder of the user's (systemd's
    CacheDirectory= for a service), never beside the installed code. numba's own default, a
    __pycache__ next to each module, put them inside site-packages/instrument/ for a regular
    install, and an editable install afterwards found that leftover folder before the real package."""
    if _os.environ.get("CACHE_DIRECTORY"):  # set by systemd for CacheDirectory=
        return _os.path.join(_os.environ["CACHE_DIRECTORY"].split(":")[0], "numba")
    base = _os.environ.get("XDG_CACHE_HOME") or _os.path.join(_os.path.expanduser("~"), ".cache")
    return _os.path.join(base, "instrument", "numba")


_os.environ.setdefault("NUMBA_CACHE_DIR", _numba_cache_dir())  # before numba is imported (it reads it then); a user's own wins
