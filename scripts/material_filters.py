#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Each material filter on the default texture-space path (shading at the hits), on a few scenes:
CPU seconds and relMSE against a per-hit reference, with per hit at the same samples and no
"filter" key (the normal filter) beside them, all from one run. Prints a Markdown table.

    scripts/material_filters.py [--texcache build/bin/texcache] [--ref-spp 512]

Every material of a scene gets the filter (a copy of the scene file, in a temporary directory
that links the scene's meshes and maps), so the table shows what the filter does where it
applies everywhere.
"""
import argparse
import json
import os
import re
import subprocess
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# (scene, integrator, resolution, spp)
CASES = [
    ("scenes/car.json", "ao", "320x180", 16),
    ("scenes/car.json", "path", "240x135", 16),
    ("validation/xord_quad_direct.json", "direct", "240x135", 16),
    ("validation/torus_city_sun.json", "path", "240x135", 16),
]
FILTERS = ["none", "gaussian", "regression"]


def load_commented_json(path):
    with open(path) as f:
        text = f.read()
    return json.loads(re.sub(r"^\s*//.*$", "", text, flags=re.M))


def run(texcache, scene, integrator, res, spp, out, shading, seed=0):
    stats = out + ".json"
    subprocess.run([texcache, "render", scene, "--shading", shading, "--integrator", integrator,
                    "--resolution", res, "--spp", str(spp), "--seed", str(seed), "-q", "-o", out,
                    "--no-png", "--stats", stats], check=True, stdout=subprocess.DEVNULL)
    with open(stats) as f:
        return json.load(f)["cpu_seconds"]


def relmse(texcache, test, ref):
    r = subprocess.run([texcache, "compare", test, ref, "--json"], check=True,
                       capture_output=True, text=True)
    return json.loads(r.stdout)["relmse"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--texcache", default=os.path.join(ROOT, "build/bin/texcache"))
    ap.add_argument("--ref-spp", type=int, default=512)
    a = ap.parse_args()
    print("| scene | integrator | method | CPU s | relMSE | relMSE / per hit's |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        # The scene folders as the scene files see them: scenes/ and validation/ side by side.
        for d in ("scenes", "validation"):
            os.makedirs(os.path.join(tmp, d))
            for entry in os.listdir(os.path.join(ROOT, d)):
                src = os.path.join(ROOT, d, entry)
                if os.path.isdir(src):
                    os.symlink(src, os.path.join(tmp, d, entry))
        for scene, integrator, res, spp in CASES:
            base = load_commented_json(os.path.join(ROOT, scene))
            stem = os.path.join(tmp, scene.replace("/", "_").replace(".json", ""))
            copies = {}
            for f in [None] + FILTERS:
                s = json.loads(json.dumps(base))
                for m in s.get("materials", {}).values():
                    if f:
                        m["filter"] = f
                path = os.path.join(tmp, os.path.dirname(scene),
                                    "copy_%s.json" % (f or "nokey"))
                with open(path, "w") as out:
                    json.dump(s, out)
                copies[f] = path
            ref = stem + "_ref_%s.exr" % integrator
            run(a.texcache, copies[None], integrator, res, a.ref_spp, ref, "hit", seed=1)
            rows = [("per hit", copies[None], "hit"), ("no key (normal)", copies[None], "texture")]
            rows += [(f, copies[f], "texture") for f in FILTERS]
            perhit = None
            for name, path, shading in rows:
                img = stem + "_%s_%s.exr" % (integrator, name.split()[0])
                cpu = run(a.texcache, path, integrator, res, spp, img, shading)
                e = relmse(a.texcache, img, ref)
                perhit = perhit or e
                print("| %s | %s | %s | %.3f | %.4f | %.2f |" %
                      (os.path.basename(scene), integrator, name, cpu, e, e / perhit), flush=True)


if __name__ == "__main__":
    main()
