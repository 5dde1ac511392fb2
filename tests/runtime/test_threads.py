"""The rig's threads carry their names to the kernel, where ``top -H`` and the benchmarks read them."""

from __future__ import annotations

import threading
from pathlib import Path

from rimd_sim.runtime.threads import MAX_OS_NAME, OS_NAMES, named_thread, set_os_name


def kernel_name(native_id: int) -> str:
    return Path(f"/proc/self/task/{native_id}/comm").read_text().rstrip("\n")


def run_in(thread_of) -> tuple[str, str]:
    """(Python name, kernel name) of a thread made by ``thread_of(target)``, read from inside it."""
    seen: list[tuple[str, str]] = []
    thread = thread_of(lambda: seen.append((threading.current_thread().name, kernel_name(threading.get_native_id()))))
    thread.start()
    thread.join(timeout=10)
    assert not thread.is_alive() and len(seen) == 1
    return seen[0]


def test_a_named_thread_has_its_name_in_python_and_in_the_kernel_and_a_plain_thread_does_not():
    assert run_in(lambda target: named_thread(target, "rimd-pacing")) == ("rimd-pacing", "rimd-pacing")
    python_name, kernel = run_in(lambda target: threading.Thread(target=target, name="rimd-other"))
    assert python_name == "rimd-other" and kernel != "rimd-other"   # what CPython before 3.14 leaves the kernel


def test_a_long_name_reaches_the_kernel_cut_to_its_fifteen_bytes_and_python_keeps_it_whole():
    name = "rimd-a-name-longer-than-the-kernel-keeps"
    assert run_in(lambda target: named_thread(target, name)) == (name, name[:MAX_OS_NAME])


def test_the_rig_threads_names_fit_the_kernel_and_naming_the_calling_thread_is_said():
    assert all(len(name.encode()) <= MAX_OS_NAME for name in OS_NAMES)

    def target():
        assert set_os_name("rimd-test-name") is True
        seen.append(kernel_name(threading.get_native_id()))

    seen: list[str] = []
    thread = threading.Thread(target=target)
    thread.start()
    thread.join(timeout=10)
    assert seen == ["rimd-test-name"]
