"""Lists a gRPC server's services through server reflection as Python's stock
grpcio-reflection asks for them (the `grpc.reflection.v1alpha` service only).

Usage: reflection.py HOST:PORT — prints one service name a line.
"""
import sys

import grpc
from grpc_reflection.v1alpha.proto_reflection_descriptor_database import (
    ProtoReflectionDescriptorDatabase,
)

with grpc.insecure_channel(sys.argv[1]) as channel:
    database = ProtoReflectionDescriptorDatabase(channel)
    for service in database.get_services():
        print(service)
