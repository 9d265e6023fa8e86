#!/usr/bin/python3
"""A client from another gRPC implementation (Debian's python3-grpcio), built only from our .proto files,
drives the real valvebench-server: health, reflection, ListBenches, SubmitRun, GetRun, GetTrace, and the
error codes. Usage: foreign_client_test.py SERVER_BINARY PROTO_DIR EXAMPLES_DIR WORK_DIR"""
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

server_bin, proto_dir, examples_dir, work = sys.argv[1:5]
shutil.rmtree(work, ignore_errors=True)
os.makedirs(work)
gen = os.path.join(work, "gen")
os.makedirs(gen)
subprocess.run(["protoc", "--proto_path=" + proto_dir, "--python_out=" + gen, "--grpc_out=" + gen,
                "--plugin=protoc-gen-grpc=/usr/bin/grpc_python_plugin",
                "valvebench/v1/spec.proto", "valvebench/v1/api.proto"], check=True)
sys.path.insert(0, gen)

import grpc  # noqa: E402
from google.protobuf import json_format  # noqa: E402
from valvebench.v1 import api_pb2, api_pb2_grpc, spec_pb2  # noqa: E402

TOKEN = "py-operator-token"
config = {"listen_address": "127.0.0.1:0", "database_path": "runs.db",
          "benches": [{"name": "emu", "kind": "emulated", "model": {"preset": "taghizadeh2009"}}],
          "tokens": [{"user": "py", "role": "operator", "token_sha256": hashlib.sha256(TOKEN.encode()).hexdigest()}]}
with open(os.path.join(work, "server.json"), "w") as f:
    json.dump(config, f)
log = open(os.path.join(work, "server.log"), "w+")
proc = subprocess.Popen([server_bin, "--config", os.path.join(work, "server.json")], stderr=log, stdout=subprocess.DEVNULL)
passed, failed = 0, 0


def check(name, cond, detail=""):
    global passed, failed
    if cond:
        passed += 1
    else:
        failed += 1
        print("FAIL: %s %s" % (name, detail))


try:
    address = None
    for _ in range(400):
        log.seek(0)
        m = re.search(r"listening on (\S+)", log.read())
        if m:
            address = m.group(1)
            break
        time.sleep(0.05)
    check("server starts", address is not None)
    channel = grpc.insecure_channel(address)
    md = [("authorization", "Bearer " + TOKEN)]

    # grpc.health.v1.Health/Check with an empty request: SERVING is field 1 = 1 -> bytes 08 01.
    health = channel.unary_unary("/grpc.health.v1.Health/Check", request_serializer=lambda b: b,
                                 response_deserializer=lambda b: b)
    check("health SERVING", health(b"", timeout=5) == b"\x08\x01")
    # Server reflection: list_services (field 7, empty string) -> the names include our service.
    refl = channel.stream_stream("/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo",
                                 request_serializer=lambda b: b, response_deserializer=lambda b: b)
    answers = list(refl(iter([b"\x3a\x00"]), timeout=5))
    check("reflection lists BenchService", any(b"valvebench.v1.BenchService" in a for a in answers), answers)

    # Bytes that are not a protobuf message (field 1 as a length-delimited string running past the end): an
    # INVALID_ARGUMENT naming the method, not gRPC's INTERNAL with an empty message.
    raw_get = channel.unary_unary("/valvebench.v1.BenchService/GetRun", request_serializer=lambda b: b,
                                  response_deserializer=lambda b: b)
    try:
        raw_get(b"\x0a\xff\xff\xff\x0f", metadata=md, timeout=5)
        check("malformed request refused", False, "the call succeeded")
    except grpc.RpcError as e:
        check("malformed request is INVALID_ARGUMENT", e.code() == grpc.StatusCode.INVALID_ARGUMENT,
              (e.code(), e.details()))
        check("malformed request names the method", "GetRun" in (e.details() or ""), e.details())

    stub = api_pb2_grpc.BenchServiceStub(channel)
    benches = stub.ListBenches(api_pb2.ListBenchesRequest(), metadata=md, timeout=5)
    check("list benches", [b.name for b in benches.benches] == ["emu"], benches)

    spec = spec_pb2.ExperimentSpec()
    with open(os.path.join(examples_dir, "standard", "e3.json")) as f:
        json_format.Parse(f.read(), spec)
    sub = stub.SubmitRun(api_pb2.SubmitRunRequest(spec=spec), metadata=md, timeout=5)
    check("submit", len(sub.run_ids) == 1, sub)
    run = None
    for _ in range(200):
        run = stub.GetRun(api_pb2.GetRunRequest(run_id=sub.run_ids[0]), metadata=md, timeout=5)
        if run.status in (api_pb2.DONE, api_pb2.FAILED, api_pb2.CANCELLED):
            break
        time.sleep(0.05)
    check("run done", run.status == api_pb2.DONE, run)
    check("metrics", run.metrics["opening_delay_s"] > 0.004, dict(run.metrics))
    samples = sum(c.samples for c in stub.GetTrace(api_pb2.GetTraceRequest(run_id=sub.run_ids[0]), metadata=md, timeout=10))
    check("trace samples", samples == 5001, samples)

    try:
        stub.ListBenches(api_pb2.ListBenchesRequest(), timeout=5)
        check("no token refused", False)
    except grpc.RpcError as e:
        check("no token -> UNAUTHENTICATED", e.code() == grpc.StatusCode.UNAUTHENTICATED, e.code())
    bad = spec_pb2.ExperimentSpec()
    bad.CopyFrom(spec)
    bad.duration_s = -1
    try:
        stub.SubmitRun(api_pb2.SubmitRunRequest(spec=bad), metadata=md, timeout=5)
        check("bad spec refused", False)
    except grpc.RpcError as e:
        check("bad spec -> INVALID_ARGUMENT naming the field",
              e.code() == grpc.StatusCode.INVALID_ARGUMENT and "duration_s" in e.details(), e.details())
finally:
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=10)

print("%d passed, %d failed" % (passed, failed))
sys.exit(1 if failed else 0)
