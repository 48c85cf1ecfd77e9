"""Tests of `mmrl data fetch`: checksums, atomic writes, skip-existing, CLI wiring.

The "remote" is a local http.server on 127.0.0.1 (random free port, in a thread) serving
../shared/data/bandai-namco-2 in its <style>/<file> layout. No internet is used.
"""
import argparse
import contextlib
import functools
import hashlib
import http.server
import json
import threading
from pathlib import Path

import pytest

from mmrl import data

REPO = Path(__file__).resolve().parents[1]


def _shared_dataset_dir():
    from conftest import require_shared_data

    return require_shared_data()


class _Handler(http.server.SimpleHTTPRequestHandler):
    """Serves a directory; counts requests; serves wrong bytes for names in `corrupt`."""

    def log_message(self, *args):  # keep test output quiet
        pass

    def do_GET(self):
        self.server.requests.append(self.path)
        if Path(self.path).name in self.server.corrupt:
            body = b"HIERARCHY\nthese are not the bytes you are looking for\n"
            self.send_response(200)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)
            return
        super().do_GET()


@contextlib.contextmanager
def serving_httpd(root):
    """(server, base URL) of a local http.server serving ``root`` (also used by test_kill_resume)."""
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Handler, directory=str(root)))
    httpd.requests, httpd.corrupt = [], set()
    thread = threading.Thread(target=httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    try:
        yield httpd, f"http://127.0.0.1:{httpd.server_address[1]}"
    finally:
        httpd.shutdown()
        httpd.server_close()
        thread.join(timeout=10)
        assert not thread.is_alive()


@pytest.fixture()
def server():
    with serving_httpd(_shared_dataset_dir()) as served:
        yield served


def _smallest_style(manifest):
    sizes = {}
    for f in manifest["files"]:
        sizes[f["style"]] = sizes.get(f["style"], 0) + f["size"]
    return min(sizes, key=sizes.get)


def _files_under(path):
    return sorted(p.relative_to(path).as_posix() for p in path.rglob("*") if p.is_file())


def test_manifest_matches_the_shared_copy():
    root = _shared_dataset_dir()
    manifest = data.dataset_manifest("bandai-namco-2")
    files = manifest["files"]
    assert len(files) == 962
    assert len({f["name"] for f in files}) == 962
    assert {f["style"] for f in files} == {"active", "elderly", "exhausted", "feminine", "masculine", "normal",
                                          "youthful"}
    assert {f["content"] for f in files} == {"walk", "walk-turn-left", "walk-turn-right", "run"}
    assert manifest["license"] == "CC BY-NC 4.0"
    on_disk = sorted(p.relative_to(root).as_posix() for p in root.glob("*/*.bvh"))
    assert on_disk == sorted(f"{f['style']}/{f['name']}" for f in files)
    for f in files[::97]:  # spot-check hashes and sizes
        blob = (root / f["style"] / f["name"]).read_bytes()
        assert len(blob) == f["size"] and hashlib.sha256(blob).hexdigest() == f["sha256"]


def test_fetch_one_style_through_local_server_then_skip_existing(server, tmp_path):
    httpd, url = server
    manifest = data.dataset_manifest()
    style = _smallest_style(manifest)
    expected = sorted(f"{style}/{f['name']}" for f in manifest["files"] if f["style"] == style)
    dest = tmp_path / "bandai"
    root = data.fetch("bandai-namco-2", styles=[style], dest=dest, base_url=url,
                      url_template=data.STYLE_DIR_URL_TEMPLATE, progress=False)
    assert root == dest
    assert _files_under(dest) == sorted(expected + ["NOTICE.txt"])
    assert len(httpd.requests) == len(expected)
    shared = _shared_dataset_dir()
    for rel in expected:
        assert (dest / rel).read_bytes() == (shared / rel).read_bytes()

    # re-running downloads nothing and touches nothing
    stamps = {rel: (dest / rel).stat().st_mtime_ns for rel in expected}
    httpd.requests.clear()
    data.fetch("bandai-namco-2", styles=[style], dest=dest, base_url=url,
               url_template=data.STYLE_DIR_URL_TEMPLATE, progress=False)
    assert httpd.requests == []
    assert stamps == {rel: (dest / rel).stat().st_mtime_ns for rel in expected}

    # a damaged local file is detected and downloaded again
    victim = dest / expected[0]
    victim.write_bytes(b"truncated")
    data.fetch("bandai-namco-2", styles=[style], dest=dest, base_url=url,
               url_template=data.STYLE_DIR_URL_TEMPLATE, progress=False)
    assert len(httpd.requests) == 1
    assert victim.read_bytes() == (shared / expected[0]).read_bytes()


def test_checksum_mismatch_raises_and_keeps_nothing(server, tmp_path):
    httpd, url = server
    manifest = data.dataset_manifest()
    files = [f for f in manifest["files"] if f["style"] == "normal" and f["content"] == "run"]
    bad = files[0]["name"]
    httpd.corrupt.add(bad)
    dest = tmp_path / "bandai"
    with pytest.raises(data.ChecksumError, match=f"checksum mismatch for {bad}.*expected"):
        data.fetch("bandai-namco-2", styles=["normal"], contents=["run"], dest=dest, base_url=url,
                   url_template=data.STYLE_DIR_URL_TEMPLATE, progress=False)
    assert not (dest / "normal" / bad).exists()
    assert [p for p in dest.rglob("*") if p.is_file()] == []  # no partial or temporary file either


def test_env_vars_select_the_source(server, tmp_path, monkeypatch):
    httpd, url = server
    monkeypatch.setenv("MMRL_DATA_URL", url)
    monkeypatch.setenv("MMRL_DATA_URL_TEMPLATE", "{base_url}/{style}/{file}")
    monkeypatch.setenv("MMRL_CACHE", str(tmp_path))
    root = data.fetch("bandai-namco-2", styles=["normal"], contents=["walk-turn-left"], progress=False)
    assert root == tmp_path / "bandai-namco-2"
    names = [f["name"] for f in data.dataset_manifest()["files"]
             if f["style"] == "normal" and f["content"] == "walk-turn-left"]
    assert sorted(p.name for p in (root / "normal").iterdir()) == sorted(names)


def test_upstream_template_is_flat_and_missing_files_are_a_clear_error(server, tmp_path):
    httpd, url = server
    # our server has the <style>/<file> layout, so the flat upstream template finds nothing
    with pytest.raises(data.DownloadError, match=r"could not download http://127\.0\.0\.1:\d+/dataset-2_"):
        data.fetch("bandai-namco-2", styles=["normal"], contents=["run"], dest=tmp_path, base_url=url,
                   url_template=data.UPSTREAM_URL_TEMPLATE, progress=False)
    assert [p for p in tmp_path.rglob("*") if p.is_file()] == []
    assert httpd.requests[0].startswith("/dataset-2_run_normal_")


def test_cli_fetch_through_local_server(server, tmp_path, capsys):
    httpd, url = server
    parser = argparse.ArgumentParser(prog="mmrl")
    data.register_cli(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["data", "fetch", "bandai-namco-2", "--styles", "normal", "--contents", "run",
                              "--dest", str(tmp_path), "--base-url", url,
                              "--url-template", "{base_url}/{style}/{file}", "--no-progress"])
    assert args.func(args) == 0
    assert "ready in" in capsys.readouterr().out
    n = sum(1 for f in data.dataset_manifest()["files"] if f["style"] == "normal" and f["content"] == "run")
    assert len(list((tmp_path / "normal").glob("*.bvh"))) == n

    httpd.corrupt.add("dataset-2_walk_normal_001.bvh")
    args = parser.parse_args(["data", "fetch", "bandai-namco-2", "--styles", "normal", "--contents", "walk",
                              "--dest", str(tmp_path), "--base-url", url,
                              "--url-template", "{base_url}/{style}/{file}", "--no-progress"])
    assert args.func(args) == 1
    assert "checksum mismatch for dataset-2_walk_normal_001.bvh" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        parser.parse_args(["data", "fetch", "bandai-namco-2", "--styles", "grumpy"])


def test_bad_arguments_are_refused(tmp_path):
    with pytest.raises(ValueError, match="unknown dataset"):
        data.fetch("cmu", dest=tmp_path)
    with pytest.raises(ValueError, match="unknown style"):
        data.fetch("bandai-namco-2", styles=["grumpy"], dest=tmp_path)
    with pytest.raises(ValueError, match="unknown content"):
        data.fetch("bandai-namco-2", contents=["dance"], dest=tmp_path)
    with pytest.raises(ValueError, match="bad URL template"):
        data.fetch("bandai-namco-2", styles=["normal"], dest=tmp_path, url_template="{base}/{file}")
    assert list(tmp_path.iterdir()) == []


def test_cache_root_honours_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("MMRL_CACHE", str(tmp_path / "c"))
    assert data.cache_root() == tmp_path / "c"
    monkeypatch.delenv("MMRL_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "x"))
    assert data.cache_root() == tmp_path / "x" / "mmrl"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert data.cache_root() == Path.home() / ".cache" / "mmrl"


def test_manifest_is_valid_json_with_hex_hashes():
    text = (REPO / "python" / "mmrl" / "manifests" / "bandai-namco-2.json").read_text()
    manifest = json.loads(text)
    assert manifest == data.dataset_manifest()
    for f in manifest["files"]:
        assert len(f["sha256"]) == 64 and int(f["sha256"], 16) >= 0 and f["size"] > 0


def test_mmrl_command_line_runs_data_fetch(server, tmp_path, capsys):
    from mmrl import cli

    httpd, url = server
    code = cli.main(["data", "fetch", "bandai-namco-2", "--styles", "normal", "--contents", "walk-turn-right",
                     "--dest", str(tmp_path), "--base-url", url, "--url-template", "{base_url}/{style}/{file}",
                     "--no-progress"])
    assert code == 0
    n = sum(1 for f in data.dataset_manifest()["files"]
            if f["style"] == "normal" and f["content"] == "walk-turn-right")
    assert len(list((tmp_path / "normal").glob("*.bvh"))) == n
