"""The glTF 2.0 rules the Khronos validator reports as errors, for the kind of file the exporter writes,
checked in Python so CI without node still checks them (tests/test_export.py also runs the real validator
when node and the gltf-validator module are there)."""
from __future__ import annotations

import base64
import json
import struct

import numpy as np

COMPONENT = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


def split_glb(raw: bytes) -> tuple[dict, bytes, list[str]]:
    """(JSON document, BIN chunk, violations of the GLB container rules)."""
    bad = []
    magic, version, length = struct.unpack_from("<4sII", raw, 0)
    if magic != b"glTF" or version != 2:
        bad.append("GLB header: magic glTF, version 2")
    if length != len(raw):
        bad.append(f"GLB length {length} != file size {len(raw)}")
    jlen, jtype = struct.unpack_from("<II", raw, 12)
    if jtype != 0x4E4F534A or jlen % 4:
        bad.append("first chunk must be JSON, padded to 4 bytes")
    js = raw[20:20 + jlen]
    if js != js.rstrip(b" ") + b" " * (len(js) - len(js.rstrip(b" "))) or b"\0" in js:
        bad.append("JSON chunk padded with something other than spaces")
    blob = b""
    pos = 20 + jlen
    if pos < len(raw):
        blen, btype = struct.unpack_from("<II", raw, pos)
        if btype != 0x004E4942 or blen % 4:
            bad.append("second chunk must be BIN, padded to 4 bytes")
        blob = raw[pos + 8:pos + 8 + blen]
        if pos + 8 + blen != len(raw):
            bad.append("bytes after the BIN chunk")
    return json.loads(js.decode("utf-8")), blob, bad


def read_gltf_file(path) -> tuple[dict, bytes, list[str]]:
    raw = open(path, "rb").read()
    if raw[:4] == b"glTF":
        return split_glb(raw)
    doc = json.loads(raw.decode("utf-8"))
    uri = doc["buffers"][0].get("uri", "")
    return doc, base64.b64decode(uri.split(",", 1)[1]) if uri.startswith("data:") else b"", []


def violations(doc: dict, blob: bytes) -> list[str]:
    """Errors the Khronos validator would report (the rules that apply to a morph-target mesh + animation)."""
    bad = []
    if doc.get("asset", {}).get("version") != "2.0":
        bad.append("asset.version must be '2.0'")
    buffers = doc.get("buffers", [])
    if len(buffers) != 1 or buffers[0]["byteLength"] > len(blob) or len(blob) - buffers[0]["byteLength"] >= 4:
        bad.append("buffer byteLength must match the binary data (up to 3 bytes of padding)")
    views = doc.get("bufferViews", [])
    for i, v in enumerate(views):
        if v["byteOffset"] + v["byteLength"] > buffers[0]["byteLength"] or v["byteLength"] < 1:
            bad.append(f"bufferView {i} outside its buffer")
        if "byteStride" in v and (v["byteStride"] % 4 or not 4 <= v["byteStride"] <= 252):
            bad.append(f"bufferView {i} byteStride must be a multiple of 4 in 4..252")
        if v.get("target") not in (None, 34962, 34963):
            bad.append(f"bufferView {i} has an invalid target")

    def read(i, view_index, offset, ctype, w, count, what="accessor"):
        v = views[view_index]
        dt = np.dtype(COMPONENT[ctype])
        start = v["byteOffset"] + offset
        if start % dt.itemsize:
            bad.append(f"{what} {i} is not aligned to its component size")
        if offset + count * dt.itemsize * w > v["byteLength"]:
            bad.append(f"{what} {i} reads past its bufferView")
            return None
        return np.frombuffer(blob, dt, count * w, start).reshape(count, w).astype(np.float64)

    def values(i):
        a = doc["accessors"][i]
        w = WIDTH[a["type"]]
        x = np.zeros((a["count"], w)) if "bufferView" not in a else \
            read(i, a["bufferView"], a.get("byteOffset", 0), a["componentType"], w, a["count"])
        if x is None:
            return np.zeros((0, w))
        sparse = a.get("sparse")
        if sparse is not None:             # 3.6.2.3: count >= 1, indices unsigned and strictly increasing
            n, si, sv = sparse["count"], sparse["indices"], sparse["values"]
            if n < 1 or n > a["count"] or si["componentType"] not in (5121, 5123, 5125):
                bad.append(f"accessor {i}: invalid sparse count or index type")
                return x
            for part in (si, sv):
                if "target" in views[part["bufferView"]] or "byteStride" in views[part["bufferView"]]:
                    bad.append(f"accessor {i}: a sparse buffer view has a target or a byteStride")
            idx = read(i, si["bufferView"], si.get("byteOffset", 0), si["componentType"], 1, n, "sparse indices of")
            val = read(i, sv["bufferView"], sv.get("byteOffset", 0), a["componentType"], w, n, "sparse values of")
            if idx is None or val is None:
                return x
            idx = idx[:, 0].astype(np.int64)
            if np.any(np.diff(idx) <= 0) or idx.max() >= a["count"]:
                bad.append(f"accessor {i}: sparse indices must increase strictly and stay below its count")
                return x
            x[idx] = val
        return x

    def bounds_exact(i, what):
        a = doc["accessors"][i]
        x = values(i)
        if "min" not in a or "max" not in a:
            bad.append(f"{what}: accessor {i} needs min and max")
        elif not (np.array_equal(np.float32(a["min"]), x.min(axis=0).astype(np.float32))
                  and np.array_equal(np.float32(a["max"]), x.max(axis=0).astype(np.float32))):
            bad.append(f"{what}: accessor {i} min/max do not match its values")
        return x

    for i, a in enumerate(doc.get("accessors", [])):
        if a["componentType"] not in COMPONENT or a["type"] not in WIDTH or a["count"] < 1:
            bad.append(f"accessor {i}: invalid componentType, type or count")
        elif not np.isfinite(values(i)).all():
            bad.append(f"accessor {i} holds NaN or infinity")
    nodes = doc.get("nodes", [])
    for s in doc.get("scenes", []):
        if any(not 0 <= n < len(nodes) for n in s.get("nodes", [])):
            bad.append("a scene refers to a node that does not exist")
    for mi, mesh in enumerate(doc.get("meshes", [])):
        for p in mesh["primitives"]:
            pa = doc["accessors"][p["attributes"]["POSITION"]]
            if pa["type"] != "VEC3" or pa["componentType"] != 5126:
                bad.append("POSITION must be float VEC3")
            pos = bounds_exact(p["attributes"]["POSITION"], "POSITION")
            if "indices" in p:
                ia = doc["accessors"][p["indices"]]
                iv = views[ia["bufferView"]]
                if ia["type"] != "SCALAR" or ia["componentType"] not in (5121, 5123, 5125) or "byteStride" in iv:
                    bad.append("indices must be unsigned SCALAR in a view without byteStride")
                idx = values(p["indices"])
                if p.get("mode", 4) == 4 and idx.size % 3:
                    bad.append("triangle indices must come in threes")
                if idx.size and idx.max() >= len(pos):
                    bad.append("an index refers to a vertex that does not exist")
            targets = p.get("targets", [])
            for k, t in enumerate(targets):
                if doc["accessors"][t["POSITION"]]["count"] != len(pos):
                    bad.append(f"morph target {k} has a different vertex count")
                bounds_exact(t["POSITION"], f"morph target {k} POSITION")
            if "weights" in mesh and len(mesh["weights"]) != len(targets):
                bad.append(f"mesh {mi}: weights must have one entry per morph target")
            names = (mesh.get("extras") or {}).get("targetNames")
            if names is not None and len(names) != len(targets):
                bad.append(f"mesh {mi}: extras.targetNames must name every morph target")
    for anim in doc.get("animations", []):
        for ch in anim["channels"]:
            s = anim["samplers"][ch["sampler"]]
            if s.get("interpolation", "LINEAR") not in ("LINEAR", "STEP", "CUBICSPLINE"):
                bad.append("invalid interpolation")
            t = bounds_exact(s["input"], "animation input")[:, 0]
            if t.size and (t[0] < 0 or np.any(np.diff(t) <= 0)):
                bad.append("animation input times must be >= 0 and strictly increasing")
            node = nodes[ch["target"]["node"]]
            if ch["target"]["path"] == "weights":
                n_targets = len(doc["meshes"][node["mesh"]]["primitives"][0].get("targets", [])) if "mesh" in node else 0
                if not n_targets:
                    bad.append("a weights channel needs a node whose mesh has morph targets")
                elif doc["accessors"][s["output"]]["count"] != t.size * n_targets:
                    bad.append("weights output count must be input count x morph targets")
    return bad
