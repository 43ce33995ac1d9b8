"""Round trip of one small UDP datagram between two processes on loopback, both sleeping in recv:
on the same core and on two cores (docs/performance.md, "Busy-polling lockstep").
Run: python docs/experiments/loop/pingpong.py"""
import os
import socket
import time

N = 20000


def round_trip_us(cpu_a: int, cpu_b: int) -> float:
    a = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    b = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    a.bind(("127.0.0.1", 0))
    b.bind(("127.0.0.1", 0))
    pid = os.fork()
    if pid == 0:
        os.sched_setaffinity(0, {cpu_b})
        for _ in range(N + 1):
            b.sendto(b.recv(2048), a.getsockname())
        os._exit(0)
    os.sched_setaffinity(0, {cpu_a})
    a.sendto(b"x" * 120, b.getsockname())   # one exchange first: both processes are running
    a.recv(2048)
    t0 = time.perf_counter()
    for _ in range(N):
        a.sendto(b"x" * 120, b.getsockname())
        a.recv(2048)
    us = (time.perf_counter() - t0) / N * 1e6
    os.waitpid(pid, 0)
    a.close()
    b.close()
    return us


cpus = sorted(os.sched_getaffinity(0))
print(f"same core ({cpus[0]}, {cpus[0]}): {round_trip_us(cpus[0], cpus[0]):.1f} us per round trip")
if len(cpus) > 1:
    print(f"two cores ({cpus[0]}, {cpus[1]}): {round_trip_us(cpus[0], cpus[1]):.1f} us per round trip")
