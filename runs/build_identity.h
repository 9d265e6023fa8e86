// Which build executed a run: the valvebench version and the SHA-256 of the executable that ran it, stored with
// the run's execution record (db::ExecutionRecord::build; docs/store.md, "Schema version 7").
//
// Why the executable's bytes and not a commit: the controllers, the emulator and the run pipeline are linked
// statically into the server and benchctl, so two runs executed by byte-identical executables ran the same code,
// whatever the checkout looked like (uncommitted edits, a Debian package, a tarball). Two builds of one commit
// may differ in bytes (another compiler, other flags): they are then called different builds, which is the safe
// side for the bench twin (docs/track.md, "The build recorded with each run"): a build that differs leaves the
// question "code or valve" to the replays; only an identical one settles it.
#pragma once

#include <string>

namespace vb::runs {

// "valvebench 0.1.0 sha256:<32 hex digits>" (the digest's first 128 bits), or "" when this process's executable
// could not be read (then no run of it claims a build). Computed once, on the first call (reading the
// executable: sha256sum takes 0.08 s over the 10 MB server here); Worker's constructor calls it, so no run's
// finish waits for it (the server, the nights and benchctl's local mode all execute through a Worker).
const std::string& ThisBuild();

// The digest part of a build ("sha256:..."), "" for one that names none: two runs ran the same code when both
// have a digest and they are equal.
std::string BuildDigest(const std::string& build);

}  // namespace vb::runs
