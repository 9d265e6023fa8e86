// The gateway's HTTP vocabulary, shared by its route files: JSON answers and errors ({"code", "message"} with
// the HTTP status of HttpStatusFor), query parameters and JSON bodies read with errors that name the field.
#pragma once

#include <google/protobuf/message.h>
#include <grpcpp/grpcpp.h>
#include <httplib.h>

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

#include "common/status.h"

namespace vb::web {

using Json = nlohmann::ordered_json;

inline constexpr char kJson[] = "application/json";
inline constexpr char kCookie[] = "vb_session";
inline constexpr int kMaxJsonDepth = 64;  // a spec nests 4 deep; a deeper body is refused before any recursive walk

// "INVALID_ARGUMENT" for grpc::StatusCode::INVALID_ARGUMENT, ...
const char* CodeName(grpc::StatusCode code);
// Text for a JSON answer: invalid UTF-8 (in a message quoting the request) becomes U+FFFD instead of throwing.
std::string Dump(const Json& j);
// `with_zeros`: fields at their default (0, false, "") are written too; proto3 JSON leaves them out otherwise,
// and a live sample at t_s = 0 would arrive without its time (the page's charts need every field).
std::string ToJson(const google::protobuf::Message& m, bool with_zeros = false);

void SendError(httplib::Response& res, grpc::StatusCode code, const std::string& message);
void SendError(httplib::Response& res, const grpc::Status& st);
void SendErrorStatus(httplib::Response& res, int http_status, const char* code, const std::string& message);
void BadRequest(httplib::Response& res, const std::string& message);
// A client::Client call's failure: the service's status as it answered (`rpc`, CallOptions::rpc_status), or,
// when the error is the client's own (rpc OK: a trace that does not decode), `st` with its matching gRPC code.
void SendClientError(httplib::Response& res, const grpc::Status& rpc, const Status& st);

// A token fit for a cookie and a metadata value: printable, no separators.
bool TokenShapeOk(const std::string& t);
// The vb_session cookie's value, "" without one.
std::string CookieToken(const httplib::Request& req);

// A query parameter as a number; false (and a 400 naming it) when present but not a number.
bool NumberParam(const httplib::Request& req, httplib::Response& res, const char* name, double* out);
bool IntParam(const httplib::Request& req, httplib::Response& res, const char* name, long long* out);
// The route's first group: a run or batch id (\d{1,15}).
std::int64_t PathId(const httplib::Request& req);
// A JSON body; false (and a 400) when it is not a JSON object.
bool BodyJson(const httplib::Request& req, httplib::Response& res, Json* out);
// A finite number to 10 significant digits, else null.
void AppendNumber(std::string* out, double v);

}  // namespace vb::web
