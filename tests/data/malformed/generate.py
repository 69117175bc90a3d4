#!/usr/bin/env python3
"""Writes the malformed-input corpus of this folder (run from anywhere; deterministic).

Every file is one way a reader's input can be wrong; EXPECTED.tsv says which error each must
give (exception type and a fragment of the message). The tables in tests/io and tests/replay
check them. Regenerate after editing: python3 tests/data/malformed/generate.py
"""
import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
files = {}

PLY_HEAD = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
files["ply_no_magic.ply"] = b"plx\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n"
files["ply_no_format.ply"] = b"ply\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n"
files["ply_bad_format.ply"] = b"ply\nformat binary_middle_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
files["ply_no_end_header.ply"] = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n1 2 3\n"
files["ply_count_not_number.ply"] = b"ply\nformat ascii 1.0\nelement vertex abc\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
files["ply_count_huge.ply"] = b"ply\nformat binary_little_endian 1.0\nelement vertex 99999999999999\nproperty float x\nproperty float y\nproperty float z\nend_header\n" + b"\0" * 24
files["ply_unknown_type.ply"] = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nproperty float y\nproperty float z\nend_header\n1 2 3\n"
files["ply_no_x.ply"] = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\nproperty float z\nend_header\n2 3\n"
files["ply_ascii_short_line.ply"] = PLY_HEAD + b"1 2 3\n4 5\n"
files["ply_ascii_not_number.ply"] = PLY_HEAD + b"1 2 3\n4 five 6\n"
files["ply_binary_truncated.ply"] = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n" + struct.pack("<6f", 1, 2, 3, 4, 5, 6) + b"\0\0"
files["ply_big_endian_truncated.ply"] = b"ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\nend_header\n" + struct.pack(">3d", 1, 2, 3)
files["ply_list_count_lies.ply"] = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n" + struct.pack("<3f", 1, 2, 3) + b"\xff" + struct.pack("<i", 0)
files["mesh_face_index_huge.ply"] = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar float vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 1e300\n"
files["mesh_face_index_nan.ply"] = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar float vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 nan\n"
files["ply_no_vertex_element.ply"] = b"ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n"
files["ply_property_before_element.ply"] = b"ply\nformat ascii 1.0\nproperty float x\nelement vertex 1\nproperty float y\nproperty float z\nend_header\n1 2\n"
files["ply_empty.ply"] = b""
files["ply_header_only_magic.ply"] = b"ply\n"

PCD = b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\n"
files["pcd_no_fields.pcd"] = b"VERSION 0.7\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2 3\n"
files["pcd_size_mismatch.pcd"] = PCD.replace(b"SIZE 4 4 4", b"SIZE 4 4") + b"DATA ascii\n1 2 3\n4 5 6\n"
files["pcd_bad_type.pcd"] = PCD.replace(b"TYPE F F F", b"TYPE F Q F") + b"DATA ascii\n1 2 3\n4 5 6\n"
files["pcd_points_huge.pcd"] = PCD.replace(b"WIDTH 2", b"WIDTH 1000000000000").replace(b"POINTS 2", b"POINTS 1000000000000") + b"DATA binary\n" + b"\0" * 24
files["pcd_width_height_mismatch.pcd"] = PCD.replace(b"HEIGHT 1", b"HEIGHT 2").replace(b"POINTS 2", b"POINTS 3") + b"DATA ascii\n1 2 3\n4 5 6\n7 8 9\n"
files["pcd_data_unknown.pcd"] = PCD + b"DATA gzip\n"
files["pcd_ascii_short_line.pcd"] = PCD + b"DATA ascii\n1 2 3\n4 5\n"
files["pcd_ascii_not_number.pcd"] = PCD + b"DATA ascii\n1 2 3\n4 x 6\n"
files["pcd_binary_truncated.pcd"] = PCD + b"DATA binary\n" + struct.pack("<4f", 1, 2, 3, 4)
files["pcd_compressed_truncated.pcd"] = PCD + b"DATA binary_compressed\n" + struct.pack("<I", 24)
files["pcd_compressed_size_lie.pcd"] = PCD + b"DATA binary_compressed\n" + struct.pack("<II", 10, 4000000000) + b"0123456789"
files["pcd_compressed_bad_lzf.pcd"] = PCD + b"DATA binary_compressed\n" + struct.pack("<II", 8, 24) + b"\xff\xff\xff\xff\xff\xff\xff\xff"
files["pcd_no_data_line.pcd"] = PCD
files["pcd_size_bad.pcd"] = PCD.replace(b"SIZE 4 4 4", b"SIZE 4 3 4") + b"DATA ascii\n1 2 3\n4 5 6\n"
files["pcd_no_xyz.pcd"] = PCD.replace(b"FIELDS x y z", b"FIELDS a b c") + b"DATA ascii\n1 2 3\n4 5 6\n"
files["pcd_empty.pcd"] = b""
files["pcd_count_zero.pcd"] = PCD.replace(b"COUNT 1 1 1", b"COUNT 1 0 1") + b"DATA ascii\n1 2 3\n4 5 6\n"
files["pcd_points_not_number.pcd"] = PCD.replace(b"POINTS 2", b"POINTS two") + b"DATA ascii\n1 2 3\n4 5 6\n"

files["xyz_empty.xyz"] = b""
files["xyz_comments_only.xyz"] = b"# exported by hand\n\n# nothing\n"
files["xyz_two_values.xyz"] = b"1 2\n3 4\n"
files["xyz_not_number.xyz"] = b"1 2 3\n1 2 abc\n"
files["xyz_ragged.xyz"] = b"1 2 3\n1 2 3 4\n"
files["xyz_five_values.xyz"] = b"1 2 3 4 5\n6 7 8 9 10\n"
files["xyz_six_ambiguous.xyz"] = b"1 2 3 0.5 7 -3\n4 5 6 0.2 9 -1\n"
files["xyz_header_without_xyz.xyz"] = b"//A B C\n1 2 3\n"
files["xyz_header_mixed.xyz"] = b"x y 3\n1 2 3\n"
files["xyz_too_many_columns.xyz"] = (" ".join(["1"] * 70) + "\n").encode()
files["xyz_colour_out_of_range.txt"] = b"//X Y Z R G B\n1 2 3 300 0 0\n"

files["conf_bmesh_short.conf"] = b"bmesh a.ply 1 2\n"
files["conf_bmesh_not_number.conf"] = b"bmesh a.ply 0 0 zero 0 0 0 1\n"
files["conf_empty.conf"] = b""
files["conf_zero_quaternion.conf"] = b"bmesh a.ply 0 0 0 0 0 0 0\n"
files["conf_only_camera.conf"] = b"camera 0 0 0 0 0 0 1\n"

def session(**over):
    import json
    s = {"created": "2026-11-23T00:00:00Z",
         "depth": {"height": 12, "invalid": 0, "unit_m": 0.0001, "width": 16},
         "device": {"kind": "test"}, "finalized": True, "format": "scanclean-rec/1",
         "frame_count": 1,
         "intrinsics": {"cx": 7.5, "cy": 5.5, "dist": [0.0, 0.0, 0.0, 0.0, 0.0], "fx": 14.0,
                        "fy": 14.0, "source": "fov"},
         "noise_model": {"name": "none"}, "registration": "off"}
    for k, v in over.items():
        if k in s["depth"]:
            s["depth"][k] = v
        else:
            s[k] = v
    return json.dumps(s, indent=2).encode()

files["session_not_json.json"] = b"{\"format\": \"scanclean-rec/1\",, }\n"
files["session_huge_number.json"] = session().replace(b'"fx": 14.0', b'"fx": 1e400')
files["session_unit_huge.json"] = session().replace(b'"unit_m": 0.0001', b'"unit_m": -1e999')
files["session_frame_count_lies.json"] = session(frame_count=5)
files["session_wrong_format.json"] = session(format="scanclean-rec/9")
files["session_not_object.json"] = b"[1, 2, 3]\n"
files["session_width_negative.json"] = session(width=-4)
files["session_width_string.json"] = session(width="four")

files["intrinsics_huge_number.json"] = b'{"fx": 525.0, "fy": 1e999, "cx": 319.5, "cy": 239.5}\n'
files["intrinsics_not_json.json"] = b'{"fx": 525.0 "fy": 525.0}\n'
files["intrinsics_fx_string.json"] = b'{"fx": "525", "fy": 525.0, "cx": 319.5, "cy": 239.5}\n'

def chunk(t, d):
    return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)

def png(w, h, depth, ctype, raw=None):
    if raw is None:
        raw = b""
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, ctype, 0, 0, 0)) + \
        chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")

files["color_ppm_size_lie.ppm"] = b"P6\n8000 8000\n255\n" + bytes(range(30))
files["color_png_size_lie.png"] = png(8000, 8000, 8, 2, b"\0" * 10)
files["color_bmp.bmp"] = b"BM" + b"\0" * 60
files["color_ppm_maxval_zero.ppm"] = b"P6\n2 2\n0\n" + bytes(12)
files["depth_png_8bit.png"] = png(4, 3, 8, 0, b"".join(b"\0" + b"\x10" * 4 for _ in range(3)))
files["depth_png_size_lie.png"] = png(60000, 60000, 16, 0, b"\0" * 10)
files["depth_pgm_truncated.pgm"] = b"P5\n4 3\n65535\n" + b"\0" * 5
files["depth_tiff_garbage.tif"] = b"II*\0" + struct.pack("<I", 4000000000) + b"\0" * 16
def tiff16_header(w, h, nbytes):
    entries = [(256, 4, 1, w), (257, 4, 1, h), (258, 3, 1, 16), (259, 3, 1, 8), (262, 3, 1, 1),
               (273, 4, 1, 8), (277, 3, 1, 1), (278, 4, 1, h), (279, 4, 1, nbytes)]
    data = b"\x78\x9c" + b"\0" * (nbytes - 2)
    ifd = struct.pack("<H", len(entries))
    for tag, typ, cnt, val in entries:
        v = struct.pack("<H", val) + b"\0\0" if typ == 3 else struct.pack("<I", val)
        ifd += struct.pack("<HHI", tag, typ, cnt) + v
    return b"II*\0" + struct.pack("<I", 8 + len(data)) + data + ifd + struct.pack("<I", 0)

files["depth_tiff_size_lie.tif"] = tiff16_header(8000, 8000, 16)
files["depth_png_not_png.png"] = b"this is not a png at all\n" * 3

files["frames_bad_header.csv"] = b"idx,ts\n0,0\n"
files["frames_non_increasing.csv"] = b"index,device_ts_us,host_ts_ns,depth,color,confidence,flags\n1,0,0,depth/000000.png,,,0\n1,10,10,depth/000000.png,,,0\n"
files["frames_missing_file.csv"] = b"index,device_ts_us,host_ts_ns,depth,color,confidence,flags\n0,0,0,depth/000009.png,,,0\n1,10,10,depth/000000.png,,,0\n"
files["frames_not_number.csv"] = b"index,device_ts_us,host_ts_ns,depth,color,confidence,flags\nzero,0,0,depth/000000.png,,,0\n"
files["frames_escaping_path.csv"] = b"index,device_ts_us,host_ts_ns,depth,color,confidence,flags\n0,0,0,../../etc/passwd,,,0\n"

for name, data in sorted(files.items()):
    with open(os.path.join(HERE, name), "wb") as f:
        f.write(data)
print(len(files), "files")
