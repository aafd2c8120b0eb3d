# Shared fixtures of the Python suite: the bundled data, the CLI, small analytic meshes.
import os
import re
import subprocess
import urllib.error
import urllib.parse
import urllib.request

import numpy as np
import pytest

DATA = os.environ.get("VOXWARP_DATA_DIR", os.path.join(os.path.dirname(__file__), "..", "..", "data"))
CLI = os.environ.get("VOXWARP_CLI", os.path.join(os.path.dirname(__file__), "..", "..", "build", "bin", "voxwarp"))


def data(name):
    return os.path.join(DATA, name)


def run_cli(*args):
    return subprocess.run([CLI, *map(str, args)], capture_output=True, text=True)


class EditServer:
    """`voxwarp edit ... --no-browser --port 0` in the background: its printed URL, port and session token."""

    def __init__(self, *args):
        self.process = subprocess.Popen([CLI, "edit", *map(str, args), "--no-browser", "--port", "0", "-q"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.process.stdout.readline()
        match = re.search(r"at (http://127\.0\.0\.1:(\d+)/(\S*))", line)
        assert match, line + self.process.stderr.read()
        self.url, self.port = match.group(1), int(match.group(2))
        self.base = "http://127.0.0.1:%d" % self.port
        self.token = urllib.parse.parse_qs(urllib.parse.urlparse(self.url).query).get("token", [""])[0]

    def request(self, method, path, body=None, headers=None, timeout=120):
        """(status, body, headers) of a request with the session's token unless `headers` says otherwise."""
        all_headers = {"X-Voxwarp-Token": self.token}
        all_headers.update(headers or {})
        data = body if body is None or isinstance(body, bytes) else body.encode()
        request = urllib.request.Request(self.base + path, data=data, method=method, headers={k: v for k, v in all_headers.items() if v is not None})
        try:
            with urllib.request.urlopen(request, timeout=timeout) as r:
                return r.status, r.read(), dict(r.headers)
        except urllib.error.HTTPError as e:
            return e.code, e.read(), dict(e.headers)

    def post(self, path, body, timeout=120):
        return self.request("POST", path, body, timeout=timeout)

    def get(self, path, **kwargs):
        return self.request("GET", path, **kwargs)

    def stop(self):
        self.process.terminate()
        self.process.wait(timeout=20)


@pytest.fixture
def server():
    """The editor's server on the bunny at 128, stopped after the test; it must exit cleanly."""
    s = EditServer(data("bunny.obj"), "--resolution", "128")
    yield s
    s.stop()
    assert s.process.returncode == 0, s.process.stderr.read()


def box(lo=(-2, -0.5, -0.5), hi=(2, 0.5, 0.5)):
    """An axis-aligned box: 8 vertices, 12 outward triangles."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    V = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0], [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], dtype=np.float64)
    F = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]], dtype=np.int32)
    return V, F


def icosphere(levels=3, radius=1.0):
    t = (1 + 5 ** 0.5) / 2
    V = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    V = [np.array(v, float) / np.linalg.norm(v) for v in V]
    F = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8),
         (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(levels):
        mid = {}

        def m(a, b):
            key = (min(a, b), max(a, b))
            if key not in mid:
                p = V[a] + V[b]
                V.append(p / np.linalg.norm(p))
                mid[key] = len(V) - 1
            return mid[key]

        F = [g for a, b, c in F for g in ((a, m(a, b), m(c, a)), (b, m(b, c), m(a, b)), (c, m(c, a), m(b, c)), (m(a, b), m(b, c), m(c, a)))]
    return radius * np.array(V), np.array(F, dtype=np.int32)


@pytest.fixture
def tmp(tmp_path):
    return tmp_path
