"""A Relief client written with another language's stock gRPC tools.

Generates Python stubs from proto/relief/v1/relief.proto with grpc_tools.protoc, asks
the server for a relief texture, checks it, and prints one JSON line.

usage: client.py PROTO_ROOT OUT_DIR SERVER SCENE_HASH
"""

import json
import sys
import os

from grpc_tools import protoc


def main() -> int:
    proto_root, out_dir, server, scene_hash = sys.argv[1:5]
    os.makedirs(out_dir, exist_ok=True)
    status = protoc.main([
        "grpc_tools.protoc",
        f"-I{proto_root}",
        f"--python_out={out_dir}",
        f"--grpc_python_out={out_dir}",
        "relief/v1/relief.proto",
    ])
    if status != 0:
        print(json.dumps({"error": f"protoc failed with {status}"}))
        return 1
    sys.path.insert(0, out_dir)
    import grpc
    from relief.v1 import relief_pb2, relief_pb2_grpc

    channel = grpc.insecure_channel(server.removeprefix("http://"))
    impostors = relief_pb2_grpc.ImpostorsStub(channel)
    request = relief_pb2.ImpostorRequest(
        scene_hash=scene_hash,
        object="sphere",
        eye=relief_pb2.Vec3(x=-3.0, y=2.0, z=5.0),
        size=64,
        depth_bits=8,
        urgency=relief_pb2.URGENCY_NOW,
        client_id="python",
        request_id=1,
    )
    final = None
    for result in impostors.Request(request, timeout=60):
        if result.final:
            final = result
    if final is None:
        print(json.dumps({"error": "no final texture"}))
        return 1
    t = final.texture
    texels = t.width * t.height
    covered = sum(1 for q in t.depth if q != 255)
    print(json.dumps({
        "width": t.width,
        "height": t.height,
        "depth_bits": t.depth_bits,
        "albedo_bytes": len(t.albedo),
        "normal_bytes": len(t.normal),
        "depth_bytes": len(t.depth),
        "texels": texels,
        "covered": covered,
        "f": [t.f.x, t.f.y, t.f.z],
    }))
    stats = impostors.Stats(relief_pb2.StatsRequest(), timeout=10)
    return 0 if stats.requests >= 1 else 1


if __name__ == "__main__":
    sys.exit(main())
