#include "client/trace_stream.h"

#include <algorithm>

#include "proto/trace_chunk.h"

namespace vb::client {

namespace v1 = valvebench::v1;

TraceStream::~TraceStream() {
  if (!finished_ && reader_) Abandon();
}

Status TraceStream::ReadChunk() {
  if (ended_) return status_;
  if (!reader_->Read(&chunk_)) {
    ended_ = finished_ = true;
    const grpc::Status st = reader_->Finish();
    status_ = st.ok() ? Status::Ok() : client_.Fail(st);
    return status_;
  }
  bytes_ += chunk_.data().size() + static_cast<std::size_t>(std::max(0, chunk_.samples())) * sizeof(double);
  if (Status bad = api::DecodeChunk(chunk_, &decoder_); !bad.ok()) {
    Abandon();
    status_ = bad;
  }
  return status_;
}

bool TraceStream::Next() {
  if (ended_) return false;
  return ReadChunk().ok() && !ended_;
}

void TraceStream::DropRows() {
  first_row_ += static_cast<std::int64_t>(decoder_.trace().samples());
  decoder_.DropRows();
}

void TraceStream::Abandon() {
  ended_ = true;
  if (finished_ || !reader_) return;
  finished_ = true;
  ctx_.TryCancel();
  while (reader_->Read(&chunk_)) {
  }
  (void)reader_->Finish();
  if (status_.ok()) status_ = Status::Aborted("trace: the read was ended before the trace's end");
}

}  // namespace vb::client
