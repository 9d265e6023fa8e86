"""Generates the gRPC stubs from ../proto into the build (protoc --python_out, Debian's grpc_python_plugin) and
records the checkout's build/bin when it exists, so the local mode finds valvebench-server. Metadata lives in
pyproject.toml."""
import os
import shutil
import subprocess

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = os.path.dirname(os.path.abspath(__file__))
PROTO_DIR = os.path.join(HERE, "..", "proto")
PROTOS = ["valvebench/v1/%s.proto" % p for p in ("spec", "config", "suite", "api")]


class BuildWithStubs(build_py):
    def run(self):
        super().run()
        protoc = shutil.which("protoc")
        plugin = shutil.which("grpc_python_plugin")
        if not protoc or not plugin:
            raise SystemExit("valvebench: protoc and grpc_python_plugin are needed to build the stubs "
                             "(Debian: apt-get install protobuf-compiler protobuf-compiler-grpc)")
        out = self.build_lib
        subprocess.run([protoc, "--proto_path=" + PROTO_DIR, "--python_out=" + out] + PROTOS, check=True)
        subprocess.run([protoc, "--proto_path=" + PROTO_DIR, "--grpc_out=" + out,
                        "--plugin=protoc-gen-grpc=" + plugin, "valvebench/v1/api.proto"], check=True)
        open(os.path.join(out, "valvebench", "v1", "__init__.py"), "a").close()
        bin_dir = os.path.abspath(os.path.join(HERE, "..", "build", "bin"))
        if os.path.exists(os.path.join(bin_dir, "valvebench-server")):
            with open(os.path.join(out, "valvebench", "_build_paths.py"), "w") as f:
                f.write("# Written by setup.py: the checkout's build tree at install time.\n"
                        "BIN_DIR = %r\nSOURCE_DIR = %r\n" % (bin_dir, os.path.dirname(HERE)))


setup(cmdclass={"build_py": BuildWithStubs})
