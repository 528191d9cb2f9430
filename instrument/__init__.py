"""A realtime stylistic walk synthesizer: HSMM style models, streaming MLPG, live control."""

import os as _os

__version__ = "0.1.0"


KERNEL_SOURCES = ("synthesis", "motion", "output")  # the subpackages whose modules hold compiled kernels


def _kernels_fingerprint() -> str:
    """A short hash of every module that holds or calls compiled kernels. numba checks a cached
    kernel against its own file only, so a kernel that calls one in another file (the stream's
    frame step calls the solver) kept code compiled against the callee as it was: after an
    update that changed the callee, a stale cache crashed the process. A cache folder per version
    of these sources is never stale (reading them takes about a millisecond)."""
    import hashlib

    digest = hashlib.blake2b(digest_size=8)
    here = _os.path.dirname(__file__)
    for package in KERNEL_SOURCES:
        folder = _os.path.join(here, package)
        for name in sorted(_os.listdir(folder)):
            if name.endswith(".py"):
                digest.update(name.encode())
                with open(_os.path.join(folder, name), "rb") as source:
                    digest.update(source.read())
    return digest.hexdigest()


def _numba_cache_dir() -> str:
    """Where numba keeps the compiled kernels: a cache folder of the user's (systemd's
    CacheDirectory= for a service), never beside the installed code, one folder per version of
    the kernels' sources (`_kernels_fingerprint`). numba's own default, a __pycache__ next to each
    module, put them inside site-packages/instrument/ for a regular install, and an editable
    install afterwards found that leftover folder before the real package."""
    if _os.environ.get("CACHE_DIRECTORY"):  # set by systemd for CacheDirectory=
        base = _os.path.join(_os.environ["CACHE_DIRECTORY"].split(":")[0], "numba")
    else:
        home = _os.environ.get("XDG_CACHE_HOME") or _os.path.join(_os.path.expanduser("~"), ".cache")
        base = _os.path.join(home, "instrument", "numba")
    return _os.path.join(base, _kernels_fingerprint())


_os.environ.setdefault("NUMBA_CACHE_DIR", _numba_cache_dir())  # before numba is imported (it reads it then); a user's own wins
