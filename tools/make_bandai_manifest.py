"""Regenerate python/mmrl/manifests/bandai-namco-2.json from a local copy of the dataset.

Usage: python tools/make_bandai_manifest.py [DATA_DIR]   (default: ../shared/data/bandai-namco-2)

DATA_DIR has the layout <style>/<file>.bvh. The manifest records, per file, the name, style,
content, byte size and SHA-256; `mmrl data fetch` verifies every download against it. Only names
and hashes are stored; the motion data itself stays out of the repository (CC BY-NC).
"""
import hashlib
import json
import re
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "python" / "mmrl" / "manifests" / "bandai-namco-2.json"
NAME = re.compile(r"^dataset-2_(?P<content>[a-z-]+)_(?P<style>[a-z]+)_(?P<number>\d{3})\.bvh$")


def main(argv):
    data_dir = Path(argv[1]) if len(argv) > 1 else REPO.parent / "shared" / "data" / "bandai-namco-2"
    files = []
    for path in sorted(data_dir.glob("*/*.bvh")):
        m = NAME.match(path.name)
        if not m or m["style"] != path.parent.name:
            raise SystemExit(f"unexpected file {path}")
        blob = path.read_bytes()
        files.append({"name": path.name, "style": m["style"], "content": m["content"],
                      "size": len(blob), "sha256": hashlib.sha256(blob).hexdigest()})
    if not files:
        raise SystemExit(f"no <style>/*.bvh files under {data_dir}")
    manifest = {
        "dataset": "bandai-namco-2",
        "title": "Bandai Namco Research Motion Dataset 2, locomotion subset (walk, walk-turn-left, walk-turn-right, run)",
        "upstream": {
            "repository": "BandaiNamcoResearchInc/Bandai-Namco-Research-Motiondataset",
            "commit": "74ead3b",
            "folder": "dataset/Bandai-Namco-Research-Motiondataset-2/data",
        },
        "license": "CC BY-NC 4.0",
        "attribution": "Bandai Namco Research Inc.",
        "files": files,
    }
    OUT.parent.mkdir(parents=True, exist_ok=True)
    # one file per line: compact and diff-friendly
    head = json.dumps({k: v for k, v in manifest.items() if k != "files"}, indent=1)[:-2]
    rows = ",\n".join("  " + json.dumps(f) for f in files)
    OUT.write_text(head + ',\n "files": [\n' + rows + "\n ]\n}\n")
    assert json.loads(OUT.read_text()) == manifest
    print(f"wrote {OUT} ({len(files)} files, {sum(f['size'] for f in files) / 1e6:.1f} MB)")


if __name__ == "__main__":
    main(sys.argv)
