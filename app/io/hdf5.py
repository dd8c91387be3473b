"""HDF5's errors, which dolfinx raises as a RuntimeError naming neither the file nor the OS error: HDF5's own
error stack is recorded instead of printed, and the OS's reason is taken from it (:class:`HDF5Errors`); a file
that failed inside HDF5 is kept open for good (:func:`abandon`). Plain ctypes on the libhdf5 dolfinx loaded:
nothing here depends on the dolfinx version."""

from __future__ import annotations

from app import interrupt

_hdf5 = {"lib": None, "looked": False, "callbacks": None}
_abandoned: list = []  # HDF5 files that failed inside HDF5: never closed (see abandon)


def _hdf5_library():
    """The libhdf5 dolfinx loaded (ctypes), or None (then errors are left as HDF5 prints them)."""
    import ctypes
    import os
    import re

    if not _hdf5["looked"]:
        _hdf5["looked"] = True
        try:
            with open("/proc/self/maps") as f:
                paths = {line.split()[-1] for line in f if "libhdf5" in line}
            path = next(p for p in sorted(paths) if re.match(r"libhdf5(_[a-z]+)?\.so", os.path.basename(p))
                        and "_hl" not in os.path.basename(p))
            lib = ctypes.CDLL(path)
            hid_t = ctypes.c_int64  # HDF5 >= 1.10

            class Error(ctypes.Structure):  # H5E_error2_t
                _fields_ = [("cls_id", hid_t), ("maj_num", hid_t), ("min_num", hid_t), ("line", ctypes.c_uint),
                            ("func_name", ctypes.c_char_p), ("file_name", ctypes.c_char_p),
                            ("desc", ctypes.c_char_p)]

            walk_t = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_uint, ctypes.POINTER(Error), ctypes.c_void_p)
            auto_t = ctypes.CFUNCTYPE(ctypes.c_int, hid_t, ctypes.c_void_p)
            lib.H5Ewalk2.argtypes = [hid_t, ctypes.c_int, walk_t, ctypes.c_void_p]
            lib.H5Eset_auto2.argtypes = [hid_t, auto_t, ctypes.c_void_p]
            lib.H5Eget_auto2.argtypes = [hid_t, ctypes.POINTER(auto_t), ctypes.POINTER(ctypes.c_void_p)]
            _hdf5.update(lib=lib, auto_t=auto_t, walk_t=walk_t, hid_t=hid_t)
        except (OSError, StopIteration, AttributeError):
            _hdf5["lib"] = None
    return _hdf5["lib"]


class HDF5Errors:
    """While entered, HDF5's automatic error report (the 'HDF5-DIAG' stack on stderr) is replaced by
    recording the stack's descriptions; :meth:`reason` then gives the OS's words where HDF5 recorded an
    errno (its serial driver does: "errno = 28, error message = 'No space left on device'"; its MPI-IO
    driver does not)."""

    def __init__(self):
        self.messages: list[str] = []
        self._saved = None

    def __enter__(self) -> HDF5Errors:
        import ctypes

        lib = _hdf5_library()
        if lib is None:
            return self
        messages = self.messages

        def walk(n, err, data):
            desc = err.contents.desc
            messages.append(desc.decode(errors="replace") if desc else "")
            return 0

        def auto(stack, data):
            lib.H5Ewalk2(stack, 0, walk_c, None)  # H5E_WALK_UPWARD: from where the error was detected
            return 0

        walk_c, auto_c = _hdf5["walk_t"](walk), _hdf5["auto_t"](auto)
        old_f, old_d = _hdf5["auto_t"](), ctypes.c_void_p()
        if lib.H5Eget_auto2(0, ctypes.byref(old_f), ctypes.byref(old_d)) >= 0:  # 0: H5E_DEFAULT
            self._saved = (old_f, old_d, walk_c, auto_c)
            lib.H5Eset_auto2(0, auto_c, None)
        return self

    def __exit__(self, *exc) -> None:
        if self._saved is not None:
            _hdf5_library().H5Eset_auto2(0, self._saved[0], self._saved[1])
            self._saved = None

    def os_reason(self) -> str | None:
        """The OS error HDF5 recorded (strerror of its errno), or None."""
        import os
        import re

        for text in self.messages:
            m = re.search(r"errno = (\d+)", text)
            if m:
                return os.strerror(int(m.group(1)))
        return None

    def reason(self, err: BaseException) -> str:
        """One line for a failed HDF5 call: the OS error if recorded, else dolfinx's and HDF5's words."""
        detail = next((m for m in self.messages if m), "")
        return self.os_reason() or (f"{err} ({detail})" if detail else str(err)).replace("\n", " ")[:300]


def abandon(xdmf_file) -> None:
    """Keep an XDMFFile that failed inside HDF5 alive and never close it: its close (also the one its
    destructor makes) would wait in a collective for a rank that left, or throw from the destructor
    (measured: std::terminate at exit). The CLI ends such a process with :func:`app.interrupt.end_process`
    (:func:`app.interrupt.finish`)."""
    _abandoned.append(xdmf_file)
    interrupt.hold_files_open()
