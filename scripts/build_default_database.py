"""Rebuild the bundled default database from ../shared/data/mocap.

    python scripts/build_default_database.py [--mocap ../shared/data/mocap]

Writes src/dancesynth/data/database/ with the licences and the CMU acknowledgement.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from dancesynth.motion.database import BUNDLED_DATABASE, build_database, collect_sources, save_database

REPO = Path(__file__).resolve().parents[1]
LICENCES = ["CMU_LICENSE.txt", "perfume-dev_example-bvh_LICENSE.txt", "yuki-koyama_bvh11_LICENSE.txt",
            "IsaacGymEnvs_LICENSE.txt", "IsaacGymEnvs_amp_motions-acknowledgement.txt",
            "beemsoft_salsa_bar_demo_README.md", "CreativeInquiry_BVH-Examples_README.md"]
ACK = ("The data used in this project was obtained from mocap.cs.cmu.edu.\n"
       "The database was created with funding from NSF EIA-0196217.")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mocap", type=Path, default=REPO.parent / "shared" / "data" / "mocap")
    ap.add_argument("--out", type=Path, default=BUNDLED_DATABASE)
    args = ap.parse_args()
    sources = collect_sources(args.mocap, manifest=REPO / "scripts" / "default_genres.toml")
    db = build_database(sources, progress=lambda p: print("analysing", Path(p).relative_to(args.mocap), file=sys.stderr))
    db.source = "shared/data/mocap (see scripts/default_genres.toml)"
    db.notes = {"acknowledgement": ACK, "licences": "see LICENSES/ and README.md in this folder"}
    for s in db.styles.values():
        s.clip_sources = tuple(str(Path(p).relative_to(args.mocap)) for p in s.clip_sources)
    if args.out.exists():
        shutil.rmtree(args.out)
    save_database(db, args.out)
    lic = args.out / "LICENSES"
    lic.mkdir()
    for name in LICENCES:
        shutil.copy(args.mocap / "licenses" / name, lic / name)
    rows = "\n".join(f"| {s.name} | {s.genre} | {s.n_clips} | {s.duration_s / 60:.1f} | "
                     f"{s.tempo_range_bpm[0]:.0f}-{s.tempo_range_bpm[1]:.0f} | {', '.join(s.clip_sources)} |"
                     for s in sorted(db.styles.values(), key=lambda s: s.name))
    (args.out / "README.md").write_text(f"""# The bundled dance database

Built by `scripts/build_default_database.py` from `../shared/data/mocap` with the genre
annotation in `scripts/default_genres.toml`. Motion is stored compactly (int16
quaternions of the joints that move, root positions in metres) with its motion beats,
kinetic energy and foot contacts.

| style | genre | clips | minutes | motion tempo (bpm) | source files |
|---|---|---|---|---|---|
{rows}

## Licences
- CMU Graphics Lab Motion Capture Database (salsa, indian, mj, whirl): free for research
  and commercial use; the data itself may not be resold (`LICENSES/CMU_LICENSE.txt`).
  BVH conversions by B. Hahne (cgspeed, "no additional restrictions"); the salsa files
  re-hosted by beemsoft, the subject-131 files by yuki-koyama/bvh11 (MIT), subject 55 from
  NVIDIA IsaacGymEnvs (BSD-3-Clause code, CMU data).
- Perfume Dev Team dance test clips (jpop): MIT, Copyright (c) 2012 Perfume Dev Team
  (`LICENSES/perfume-dev_example-bvh_LICENSE.txt`).

## Acknowledgement
{ACK}
""")
    print(f"wrote {args.out}: " + ", ".join(f"{s.name} ({s.n_clips} clips)" for s in db.styles.values()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
