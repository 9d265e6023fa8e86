// A stored trace read chunk by chunk (Client::OpenTrace): what GetTrace sends, decoded by the one decoder
// (common/trace_columns.h through proto/trace_chunk.h), one chunk's rows held at a time, so a door can pass on a
// trace of any length (the web's CSV download) or stop at a size (the web's HDF5/MAT files, the batch report).
#pragma once

#include <grpcpp/grpcpp.h>

#include <cstddef>
#include <cstdint>
#include <memory>

#include "client/client.h"
#include "common/status.h"
#include "common/trace_columns.h"

namespace vb::client {

// The stream's calls report through the view it was opened with: that view's CallOptions::rpc_status must live
// as long as the stream.
class TraceStream {
 public:
  TraceStream(const TraceStream&) = delete;
  TraceStream& operator=(const TraceStream&) = delete;
  // A stream left before its end cancels the call and drains it (no reader is destroyed mid-call).
  ~TraceStream();

  // The rows decoded so far that the caller has not dropped: the header (channels, t0_s, sample_period_s,
  // total_samples, decimated) and the columns. After OpenTrace: the first chunk's rows.
  const TraceColumns& rows() const { return decoder_.trace(); }
  // The index in the whole trace of rows()'s first row (rows dropped before it).
  std::int64_t first_row() const { return first_row_; }
  // Bytes received so far: every chunk's sample data and its rows' times (8 bytes a row).
  std::size_t bytes() const { return bytes_; }

  // Reads the next chunk and appends its rows; false at the end or on an error (status()).
  bool Next();
  // Forgets the rows read so far (streaming: memory stays at a chunk), keeps the header and the position.
  void DropRows();
  // Ends the call before the trace's end (a size limit, a reader gone): cancels it and drains it.
  void Abandon();
  // Ok once the trace ended cleanly; DataLoss for a chunk that does not decode; the call's error otherwise.
  Status status() const { return status_; }
  // Every row read (Next() until false, status() ok): the whole trace.
  TraceColumns TakeAll() { return decoder_.Take(); }

 private:
  friend class Client;
  explicit TraceStream(const Client& client) : client_(client) {}
  Status ReadChunk();  // one chunk into the decoder; sets status_ at the end or on an error

  Client client_;  // a view (credentials, rpc_status) for the call's errors
  grpc::ClientContext ctx_;
  std::unique_ptr<grpc::ClientReader<valvebench::v1::TraceChunk>> reader_;
  valvebench::v1::TraceChunk chunk_;
  TraceDecoder decoder_;
  Status status_;
  std::int64_t first_row_ = 0;
  std::size_t bytes_ = 0;
  bool finished_ = false;  // Finish was called
  bool ended_ = false;     // no chunk will come
};

}  // namespace vb::client
