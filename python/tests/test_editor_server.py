# The editor's server (`voxwarp edit`) without a browser: who it lets in (Host, Origin, the session token), the
# work it accepts (--max-resolution, --max-memory), and that refusals and broken requests leave it answering.
# The page through the printed URL, in Chromium: test_editor.py.
import json
import re
import socket
import subprocess
import threading
import time

import pytest

from conftest import CLI, EditServer, data

PLY = b"ply\nformat binary_little_endian"


@pytest.fixture(scope="module")
def box_server():
    s = EditServer(data("box.obj"), "--resolution", "32")
    yield s
    s.stop()


def refused(code, body, headers, status=403):
    """A refusal: `status`, a JSON error, nothing of the model."""
    assert code == status, (code, body[:80])
    assert not body.startswith(b"ply") and "X-Voxwarp-Model" not in headers and "X-Voxwarp-Report" not in headers, body[:80]
    return json.loads(body)["error"]


def test_the_printed_url_carries_a_fresh_128_bit_token(box_server):
    assert re.fullmatch(r"[0-9a-f]{32}", box_server.token), box_server.url
    assert box_server.url == "http://127.0.0.1:%d/?token=%s" % (box_server.port, box_server.token)
    other = EditServer(data("box.obj"), "--resolution", "32")
    try:
        assert other.token != box_server.token
    finally:
        other.stop()


def test_a_foreign_host_is_refused_on_every_path(box_server):
    port = box_server.port
    good = open(data("box_twist.json"), "rb").read()
    for host in ("evil.example:%d" % port, "127.0.0.1.evil.example:%d" % port, "localhost:%d" % (port + 1), "127.0.0.1", "localhost", "[::1]:%d0" % port, ""):
        for method, path, body in (("GET", "/", None), ("GET", "/editor.js", None), ("GET", "/api/model", None), ("GET", "/api/edit", None),
                                   ("GET", "/nowhere", None), ("POST", "/api/deform?resolution=16", good), ("POST", "/api/nowhere", b"{}")):
            code, answer, headers = box_server.request(method, path, body, headers={"Host": host})
            assert "Host must be" in refused(code, answer, headers), (host, path)
    # The server's own names.
    for host in ("127.0.0.1:%d" % port, "localhost:%d" % port, "LocalHost:%d" % port, "[::1]:%d" % port):
        code, answer, _ = box_server.get("/api/model", headers={"Host": host})
        assert code == 200 and answer.startswith(PLY), host


def test_a_missing_or_wrong_token_is_refused_on_the_api(box_server):
    good = open(data("box_twist.json"), "rb").read()
    wrong = ("0" if box_server.token[0] != "0" else "1") + box_server.token[1:]
    for token in (None, "", wrong, box_server.token[:-1], box_server.token + "0", box_server.token.upper()):
        for method, path, body in (("GET", "/api/model", None), ("GET", "/api/edit", None), ("POST", "/api/deform?resolution=16", good)):
            code, answer, headers = box_server.request(method, path, body, headers={"X-Voxwarp-Token": token})
            assert "X-Voxwarp-Token" in refused(code, answer, headers), (token, path)
    # In the query string it does not count: the page sends it as a header, which another site cannot set.
    code, answer, headers = box_server.request("GET", "/api/model?token=" + box_server.token, headers={"X-Voxwarp-Token": None})
    refused(code, answer, headers)
    # The page and its scripts hold no secret: they load without it (and ask the API with it).
    code, page, _ = box_server.get("/", headers={"X-Voxwarp-Token": None})
    assert code == 200 and b"<html" in page.lower()
    code, answer, _ = box_server.post("/api/deform?resolution=16", good)
    assert code == 200 and answer.startswith(PLY)


def test_a_foreign_origin_is_refused(box_server):
    port = box_server.port
    good = open(data("box_twist.json"), "rb").read()
    for origin in ("http://evil.example", "null", "http://127.0.0.1:%d" % (port + 1), "https://127.0.0.1:%d" % port, "http://127.0.0.1.evil.example:%d" % port):
        # A cross-site form post (text/plain needs no preflight), with the right token even.
        code, answer, headers = box_server.request("POST", "/api/deform?resolution=16", good, headers={"Origin": origin, "Content-Type": "text/plain"})
        assert "cross-origin" in refused(code, answer, headers), origin
        code, answer, headers = box_server.get("/api/model", headers={"Origin": origin})
        refused(code, answer, headers)
    for origin in ("http://127.0.0.1:%d" % port, "http://localhost:%d" % port):
        code, answer, headers = box_server.request("POST", "/api/deform?resolution=16", good, headers={"Origin": origin, "Content-Type": "application/json"})
        assert code == 200 and answer.startswith(PLY), origin
        assert not any(k.lower().startswith("access-control-") for k in headers), headers


def test_no_answer_allows_another_origin(box_server):
    good = open(data("box_twist.json"), "rb").read()
    answers = [box_server.get(p) for p in ("/", "/api/model", "/api/edit", "/nowhere")]
    answers += [box_server.request("OPTIONS", "/api/deform", headers={"Origin": "http://evil.example", "Access-Control-Request-Method": "POST"})]
    answers += [box_server.post("/api/deform?resolution=16", good)]
    for code, _, headers in answers:
        assert not any(k.lower().startswith("access-control-allow") for k in headers), (code, headers)


def test_over_cap_resolutions_and_memory_are_refused_with_the_limit():
    good = open(data("box_twist.json"), "rb").read()
    s = EditServer(data("box.obj"), "--resolution", "32")  # cap: twice the resolution
    try:
        assert "[8, 64]" in refused(*s.post("/api/deform?resolution=65", good), status=400)
        code, answer, _ = s.post("/api/deform?resolution=64", good)
        assert code == 200 and answer.startswith(PLY)
    finally:
        s.stop()
    s = EditServer(data("box.obj"), "--resolution", "32", "--max-resolution", "40", "--max-memory", "0.00001")
    try:
        assert "[8, 40]" in refused(*s.post("/api/deform?resolution=41", good), status=400)
        message = refused(*s.post("/api/deform?resolution=40", good), status=503)
        assert "needs about" in message and "limit of 10.49 KiB" in message, message  # the estimate, against the limit
    finally:
        s.stop()
    r = subprocess.run([CLI, "edit", data("box.obj"), "-r", "64", "--max-resolution", "32", "--no-browser", "--port", "0"], capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "--max-resolution" in r.stderr, r.stderr


def test_token_options():
    good = open(data("box_twist.json"), "rb").read()
    token = "scripted-token_0123456789"
    s = EditServer(data("box.obj"), "-r", "32", "--token", token)
    try:
        assert s.token == token and s.url.endswith("?token=" + token)
        code, answer, _ = s.post("/api/deform?resolution=16", good)
        assert code == 200 and answer.startswith(PLY)
        refused(*s.get("/api/model", headers={"X-Voxwarp-Token": "scripted-token_0123456780"}))
    finally:
        s.stop()
    for bad in ("short", "has space in it 0123456789", "quote\"0123456789abcdef"):
        r = subprocess.run([CLI, "edit", data("box.obj"), "--token", bad, "--no-browser", "--port", "0"], capture_output=True, text=True, timeout=60)
        assert r.returncode != 0 and "--token" in r.stderr, (bad, r.stderr)
    # --no-token: a warning even with -q, no token in the URL, the API open to local requests; the Host check stays.
    s = EditServer(data("box.obj"), "-r", "32", "--no-token")
    try:
        assert s.token == "" and s.url.endswith(":%d/" % s.port)
        code, answer, _ = s.get("/api/model", headers={"X-Voxwarp-Token": None})
        assert code == 200 and answer.startswith(PLY)
        refused(*s.get("/api/model", headers={"Host": "evil.example:%d" % s.port}))
    finally:
        s.stop()
        assert "--no-token" in s.process.stderr.read()


def test_server_survives_200_bad_requests(server):
    good = open(data("bunny_ear.json"), "rb").read()
    statuses = {}

    def raw(payload, read=True):
        with socket.create_connection(("127.0.0.1", server.port), timeout=10) as s:
            s.sendall(payload)
            if read:
                s.settimeout(10)
                try:
                    return s.recv(200)
                except socket.timeout:
                    return b""
        return b""

    host = "Host: 127.0.0.1:%d\r\nX-Voxwarp-Token: %s\r\n" % (server.port, server.token)
    for i in range(200):
        kind = i % 12
        if kind == 0:
            code, body, _ = server.post("/api/deform", b"{ not json")
            assert code == 400 and json.loads(body)["error"].startswith("request: not valid JSON"), body
        elif kind == 1:
            code, body, _ = server.post("/api/deform", '{"edits": [{"constraints": [{"move": [0, 0, "x"], "to": [0, 1, 0]}]}]}')
            assert code == 400 and "request: edits[0].constraints[0].move[2]" in json.loads(body)["error"], body
        elif kind == 2:
            code, body, _ = server.post("/api/deform", b"x" * (17 << 20))
            assert code == 413, code
        elif kind == 3:
            code, body, _ = server.post("/api/nowhere", b"{}")
            assert code == 404, code
        elif kind == 4:  # the connection closes in the middle of the headers
            raw(b"POST /api/deform HTTP/1.1\r\n" + host.encode() + b"Content-Len", read=False)
            code = "closed"
        elif kind == 5:  # ... or of the body
            raw(b"POST /api/deform HTTP/1.1\r\n" + host.encode() + b"Content-Length: 1000\r\n\r\n{\"edits\"", read=False)
            code = "closed"
        elif kind == 6:
            code, body, _ = server.post("/api/deform?resolution=99999", good)
            assert code == 400 and "[8, 256]" in json.loads(body)["error"], body
        elif kind == 7:
            reply = raw(b"GARBAGE\r\n\r\n")
            code = reply[:12].decode(errors="replace")
        elif kind == 8:
            code = server.request("POST", "/api/deform", good, headers={"Host": "evil.example:%d" % server.port})[0]
            assert code == 403
        elif kind == 9:
            code = server.request("POST", "/api/deform", good, headers={"X-Voxwarp-Token": None})[0]
            assert code == 403
        elif kind == 10:
            code = server.request("POST", "/api/deform", good, headers={"Origin": "http://evil.example", "Content-Type": "text/plain"})[0]
            assert code == 403
        else:
            code = server.request("POST", "/api/deform?resolution=257", good)[0]
            assert code == 400
        statuses[kind] = code
    code, body, headers = server.post("/api/deform?resolution=48", good)
    assert code == 200 and body.startswith(PLY), (code, body[:100])
    report = json.loads(headers["X-Voxwarp-Report"])
    assert report["edits"][0]["constraints"][0]["residual_voxels"] < 1e-6
    assert server.process.poll() is None


def test_a_newer_request_supersedes_the_running_one():
    s = EditServer(data("bunny.obj"), "--resolution", "128", "--max-resolution", "384")
    try:
        good = open(data("bunny_ear.json"), "rb").read()
        results = {}

        def slow():
            results["slow"] = s.post("/api/deform?resolution=384", good)[0]

        thread = threading.Thread(target=slow)
        thread.start()
        time.sleep(0.3)
        results["fast"] = s.post("/api/deform?resolution=32", good)[0]
        thread.join()
        # The slow request (voxelizing at 384 alone takes longer than the 0.3 s head start) is cancelled for the
        # newer one, which is answered.
        assert results == {"fast": 200, "slow": 409}, results
    finally:
        s.stop()
