#!/usr/bin/env bash
# Regenerates the committed seed corpora in fuzz/corpus/<target>/.
#
#   fuzz/make-seeds.sh [path/to/mapc]
#
# Needs a built `mapc` (default: target/release/mapc, else `cargo run
# --release -p mapc --`) and python3 (standard library only). Every seed is
# kept under 200 KB. Rerun after a .refdb format change (the regression test
# `refdb_seeds_are_valid_databases` fails until the seeds match the reader).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(dirname "$here")"
cd "$root"
if [[ $# -ge 1 ]]; then
    mapc=("$1")
elif [[ -x target/release/mapc ]]; then
    mapc=(target/release/mapc)
else
    mapc=(cargo run --quiet --release -p mapc --)
fi
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

corpus="$here/corpus"
rm -rf "$corpus"
mkdir -p "$corpus"/{refdb,mapfile,scanio,bag,cdr}

# --- refdb: small databases, minus the 16-byte prefix the harness supplies.
"${mapc[@]}" synth --kind office --width 120 --height 90 -o "$work" --name tiny -q
"${mapc[@]}" build "$work/tiny.yaml" -o "$work/tiny.refdb" --fit-queries 10 --beams 90 -q
"${mapc[@]}" build "$work/tiny.yaml" -o "$work/tiny-360.refdb" --fit-queries 10 --beams 90 \
    --fov-windows none -q
"${mapc[@]}" build "$work/tiny.yaml" -o "$work/tiny-ms.refdb" --fit-queries 0 --beams 64 \
    --fov-windows 180 --selection match-score --refine-iters 3 --max-points 64 -q
"${mapc[@]}" synth --kind cave --width 60 --height 50 -o "$work" --name cave -q
"${mapc[@]}" build "$work/cave.yaml" -o "$work/cave.refdb" --fit-queries 0 --beams 32 \
    --fov-windows none -q
# A coarse-search index forced on the small map, narrow enough to have
# internal nodes, on both views (full and 180 degrees).
"${mapc[@]}" build "$work/tiny.yaml" -o "$work/tiny-index.refdb" --fit-queries 0 --beams 48 \
    --fov-windows 180 --index-min-sites 1 --index-leaf-size 2 --index-beam 2 --index-leaves 2 \
    --max-points 48 -q
for db in tiny tiny-360 tiny-ms cave tiny-index; do
    tail -c +17 "$work/$db.refdb" > "$corpus/refdb/$db"
done

# --- mapfile and scanio: built by python (PNG and gzip writers included).
python3 - "$work" "$corpus" <<'PY'
import gzip, math, os, struct, sys, zlib

work, corpus = sys.argv[1], sys.argv[2]
SEP = b"\n%%IMAGE%%\n"  # refloc_fuzz::MAP_SEPARATOR

def yaml(image="map.pgm", res="0.05", origin="[0.0, 0.0, 0.0]", extra=""):
    return (f"image: {image}\nresolution: {res}\norigin: {origin}\nnegate: 0\n"
            f"occupied_thresh: 0.65\nfree_thresh: 0.196\n{extra}").encode()

def room(w, h):
    """0 = obstacle, 254 = free, 205 = unknown; a walled room with a pillar."""
    px = []
    for y in range(h):
        row = []
        for x in range(w):
            wall = x in (0, w - 1) or y in (0, h - 1)
            pillar = w // 3 <= x < w // 3 + 2 and h // 3 <= y < h // 3 + 2
            unknown = x > w - 4 and y < 3
            row.append(205 if unknown else 0 if (wall or pillar) else 254)
        px.append(row)
    return px

def pgm_p5(px):
    h, w = len(px), len(px[0])
    return f"P5\n{w} {h}\n255\n".encode() + bytes(v for r in px for v in r)

def pgm_p5_16(px):
    h, w = len(px), len(px[0])
    return f"P5 {w} {h} 65535\n".encode() + b"".join(struct.pack(">H", v * 257) for r in px for v in r)

def pgm_p2(px):
    h, w = len(px), len(px[0])
    body = "\n".join(" ".join(str(v) for v in r) for r in px)
    return f"P2\n# plain\n{w} {h}\n255\n{body}\n".encode()

def pbm_p1(px):
    h, w = len(px), len(px[0])
    body = "\n".join(" ".join("1" if v == 0 else "0" for v in r) for r in px)
    return f"P1\n{w} {h}\n{body}\n".encode()

def png(px, mode):
    """mode: 0 grey, 4 grey+alpha, 2 RGB, 6 RGBA (8-bit)."""
    h, w = len(px), len(px[0])
    raw = b""
    for y, r in enumerate(px):
        raw += b"\x00"
        for x, v in enumerate(r):
            a = 0 if (x == 1 and y == 1) else 255
            raw += {0: bytes([v]), 4: bytes([v, a]), 2: bytes([v, v, v]),
                    6: bytes([v, max(v - 20, 0), v, a])}[mode]
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, mode, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))

def put(target, name, data):
    assert len(data) < 200_000, (name, len(data))
    with open(os.path.join(corpus, target, name), "wb") as f:
        f.write(data)

tiny_pgm = open(os.path.join(work, "tiny.pgm"), "rb").read()
px = room(16, 12)
put("mapfile", "synth-office", yaml() + SEP + tiny_pgm)
put("mapfile", "p5-trinary", yaml(extra="mode: trinary\n") + SEP + pgm_p5(px))
put("mapfile", "p5-16bit-negate", yaml(res="0.1", extra="negate: 1\n").replace(b"negate: 0\n", b"")
    + SEP + pgm_p5_16([[255 - v for v in r] for r in px]))
put("mapfile", "p2-raw", yaml(extra="mode: raw\n") + SEP
    + pgm_p2([[100 if v == 0 else 0 if v == 254 else 255 for v in r] for r in px]))
put("mapfile", "p1-bitmap", yaml(origin="[-1.5, 2.0, 0.3]") + SEP + pbm_p1(px))
put("mapfile", "png-grey-scale", yaml(extra="mode: scale\n") + SEP + png(px, 0))
put("mapfile", "png-grey-alpha", yaml() + SEP + png(px, 4))
put("mapfile", "png-rgb", yaml(res="1e-2") + SEP + png(px, 2))
put("mapfile", "png-rgba-quoted", (
    b"# a map_server description\n"
    b"image: \"map.pgm\"\nresolution: '0.05'\norigin: [ -3, 4.5e0, !!float 0 ]\n"
    b"negate: false\noccupied_thresh: 0.9\nfree_thresh: 0.1\nmode: Trinary\nextra_key: {a: [1, 2]}\n")
    + SEP + png(px, 6))
put("mapfile", "anchors-tags", (
    b"%YAML 1.2\n---\nbase: &r 0.05\nimage: !custom map.pgm\nresolution: *r\n"
    b"origin: !!seq [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.196\n...\n")
    + SEP + pgm_p5(px))

# --- scanio
def jl(**kw):
    import json
    return json.dumps(kw, separators=(",", ":"))

n = 90
rng = [round(2.0 + math.sin(3 * k * 2 * math.pi / n), 3) for k in range(n)]
rng_null = [None if k % 11 == 0 else v for k, v in enumerate(rng)]
pts = [[round(r * math.cos(-math.pi + k * 2 * math.pi / n), 3),
        round(r * math.sin(-math.pi + k * 2 * math.pi / n), 3)] for k, r in enumerate(rng)]
lines = [
    "# scans for the fuzzer",
    jl(id="a", angle_min=-math.pi, angle_max=math.pi - 2 * math.pi / n,
       angle_increment=2 * math.pi / n, range_min=0.05, range_max=30.0, ranges=rng_null,
       truth=[1.0, 2.0, 0.5]),
    "",
    jl(id=7, angle_min=1.5, angle_increment=-0.02, range_max=5, ranges=rng[:40],
       intensities=[1] * 40, header={"stamp": 3}),
    jl(points=pts[:30], range_max=12.5, truth=None),
    '{"angle_min":-1e400,"angle_increment":1e-3,"ranges":[1,2,null,1e999,-0.0,3]}',
    '{"angle_min":0,"angle_increment":0.1,"ranges":[1,2],"ranges":[3]}',
]
put("scanio", "jsonl", ("\n".join(lines) + "\n").encode())
put("scanio", "jsonl-crlf-bom", ("\ufeff" + "\r\n".join(lines[1:3]) + "\r\n").encode())

def flaser(kw, n, r):
    return f"{kw} {n} " + " ".join(f"{r:.2f}" for _ in range(n)) + " 1.5 -2.5 0.75 1.5 -2.5 0.75 12.5 host 12.6"

carmen = [
    "# CARMEN log",
    "PARAM robot_front_laser_max 20.0",
    "PARAM robot_rear_laser_max 8",
    "ODOM 0 0 0 0 0 0 1.0 host 1.0",
    flaser("FLASER", 180, 2.5),
    flaser("RLASER", 181, 1.25),
    flaser("FLASER", 10, 0.5),
    "ROBOTLASER1 0 -1.25 2.5 0.02 50.0 0.01 0 3 1.0 60 2.0 2 7 8 1 2 0.1 1 2 0.1 0 0 0.5 0.5 0 3.0 host 3.1",
    "TRUEPOS 1 2 3 1 2 3 4 host 5",
    "SYNC 1 host 2",
]
put("scanio", "carmen", ("\n".join(carmen) + "\n").encode())
put("scanio", "mixed", b"# header\nhello world\n{\"points\":[[1,2]]}\nFLASER 1 1 0 0 0 0 0 0\n"
    + b"ROBOTLASER2 0 -1.5 3.1 0.5 50 0.01 0 3 1 2 3 0 1 2 3 4 5 6\n")
put("scanio", "jsonl-gz", gzip.compress(("\n".join(lines[:4]) + "\n").encode(), mtime=0))

# Three scans of the tiny map's 90-beam sensor, for the recording below.
with open(os.path.join(work, "scans3.jsonl"), "w") as f:
    for k in range(3):
        f.write(jl(id=f"r{k}", angle_min=-math.pi, angle_increment=2 * math.pi / n,
                   range_max=30.0, ranges=[round(v + 0.1 * k, 3) for v in rng]) + "\n")

# --- cdr: sensor_msgs/msg/LaserScan messages (XCDR1), and bag: MCAP files
# written record by record from the MCAP spec (no mcap library needed).
def cdr(ranges, intensities=(), little=True, frame="laser", sec=1733270400, nsec=250):
    e = "<" if little else ">"
    out = bytearray(b"\x00\x01\x00\x00" if little else b"\x00\x00\x00\x00")
    def align(k):
        while (len(out) - 4) % k:
            out.append(0)
    def u32(v):
        align(4)
        out.extend(struct.pack(e + "I", v))
    def f32(v):
        align(4)
        out.extend(struct.pack(e + "f", v))
    u32(sec)
    u32(nsec)
    u32(len(frame) + 1)
    out.extend(frame.encode() + b"\x00")
    for v in (-math.pi, math.pi, 2 * math.pi / max(len(ranges), 1), 0.0, 0.1, 0.05, 30.0):
        f32(v)
    for seq in (ranges, intensities):
        u32(len(seq))
        for v in seq:
            f32(v)
    return bytes(out)

ring = [2.0 + math.sin(3 * k * 2 * math.pi / 24) for k in range(24)]
put("cdr", "le-intensities", cdr(ring, [100.0] * 24))
put("cdr", "be", cdr(ring[:10], little=False, frame="base_scan"))
put("cdr", "inf-nan-empty-frame", cdr([math.inf, math.nan, -1.0, 0.0, 1e30], frame=""))
put("cdr", "empty-ranges", cdr([]))

MCAP_MAGIC = b"\x89MCAP0\r\n"

def s_(t):
    b = t.encode()
    return struct.pack("<I", len(b)) + b

def rec(op, body):
    return struct.pack("<BQ", op, len(body)) + body

def header():
    return rec(0x01, s_("ros2") + s_("refloc make-seeds"))

def schema(i, name, text):
    return rec(0x03, struct.pack("<H", i) + s_(name) + s_("ros2msg") + struct.pack("<I", len(text)) + text.encode())

def channel(i, schema_id, topic, encoding="cdr"):
    meta = s_("offered_qos_profiles") + s_("")
    return rec(0x04, struct.pack("<HH", i, schema_id) + s_(topic) + s_(encoding) + struct.pack("<I", len(meta)) + meta)

def message(ch, seq, t, data):
    return rec(0x05, struct.pack("<HIQQ", ch, seq, t, t) + data)

def chunk(records):
    body = struct.pack("<QQQI", 0, 10**9, len(records), zlib.crc32(records)) + s_("")
    return rec(0x06, body + struct.pack("<Q", len(records)) + records)

def finish(data):
    return data + rec(0x0F, struct.pack("<I", 0)) + rec(0x02, struct.pack("<QQI", 0, 0, 0)) + MCAP_MAGIC

LASER = ("std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n"
         "float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n"
         "float32[] ranges\nfloat32[] intensities\n")
scans = [cdr(ring, [1.0] * 24), cdr(ring[::2], little=False), cdr(ring)[:30], cdr(ring[:3], nsec=10**9 + 5)]
base = (schema(1, "sensor_msgs/msg/LaserScan", LASER) + channel(1, 1, "/scan")
        + schema(2, "std_msgs/msg/String", "string data\n") + channel(2, 2, "/chatter"))
msgs = b"".join(message(1, k, 100 + k, d) for k, d in enumerate(scans))
msgs += message(2, 0, 150, b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00")
plain = finish(MCAP_MAGIC + header() + base + msgs)
put("bag", "plain", plain)
put("bag", "cut", plain[: len(plain) * 3 // 4])
rear = schema(3, "sensor_msgs/LaserScan", LASER) + channel(3, 3, "/scan_rear")
put("bag", "chunked-two-scan-topics",
    finish(MCAP_MAGIC + header() + chunk(base + rear + msgs + message(3, 0, 120, scans[1]))))
put("bag", "no-scan-topic", finish(MCAP_MAGIC + header() + schema(2, "std_msgs/msg/String", "string data\n")
                                 + channel(2, 2, "/chatter") + message(2, 0, 1, b"\x00\x01\x00\x00")))
PY
# A recording `mapc localize --mcap` writes (zstd chunk, summary section):
# /scan LaserScans beside the map, pose and TF topics.
"${mapc[@]}" -q localize "$work/tiny.refdb" "$work/scans3.jsonl" --mcap "$corpus/bag/recording" >/dev/null
ls -l "$corpus"/*
