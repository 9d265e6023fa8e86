#include "web/http.h"

#include "proto/grpc_status.h"

#include <fmt/format.h>
#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <iterator>
#include <stdexcept>

#include "web/gateway.h"

namespace vb::web {

const char* CodeName(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK: return "OK";
    case grpc::StatusCode::CANCELLED: return "CANCELLED";
    case grpc::StatusCode::INVALID_ARGUMENT: return "INVALID_ARGUMENT";
    case grpc::StatusCode::DEADLINE_EXCEEDED: return "DEADLINE_EXCEEDED";
    case grpc::StatusCode::NOT_FOUND: return "NOT_FOUND";
    case grpc::StatusCode::ALREADY_EXISTS: return "ALREADY_EXISTS";
    case grpc::StatusCode::PERMISSION_DENIED: return "PERMISSION_DENIED";
    case grpc::StatusCode::RESOURCE_EXHAUSTED: return "RESOURCE_EXHAUSTED";
    case grpc::StatusCode::FAILED_PRECONDITION: return "FAILED_PRECONDITION";
    case grpc::StatusCode::ABORTED: return "ABORTED";
    case grpc::StatusCode::OUT_OF_RANGE: return "OUT_OF_RANGE";
    case grpc::StatusCode::UNIMPLEMENTED: return "UNIMPLEMENTED";
    case grpc::StatusCode::INTERNAL: return "INTERNAL";
    case grpc::StatusCode::UNAVAILABLE: return "UNAVAILABLE";
    case grpc::StatusCode::DATA_LOSS: return "DATA_LOSS";
    case grpc::StatusCode::UNAUTHENTICATED: return "UNAUTHENTICATED";
    default: return "UNKNOWN";
  }
}



// Text for a JSON answer: invalid UTF-8 (in a message quoting the request) becomes U+FFFD instead of throwing.
std::string Dump(const Json& j) { return j.dump(-1, ' ', false, Json::error_handler_t::replace); }

void SendError(httplib::Response& res, grpc::StatusCode code, const std::string& message) {
  res.status = HttpStatusFor(code);
  res.set_content(Dump(Json{{"code", CodeName(code)}, {"message", message}}), kJson);
}
void SendErrorStatus(httplib::Response& res, int http_status, const char* code, const std::string& message) {
  res.status = http_status;
  res.set_content(Dump(Json{{"code", code}, {"message", message}}), kJson);
}
void SendError(httplib::Response& res, const grpc::Status& st) { SendError(res, st.error_code(), st.error_message()); }
void BadRequest(httplib::Response& res, const std::string& message) {
  SendError(res, grpc::StatusCode::INVALID_ARGUMENT, message);
}

// `with_zeros`: fields at their default (0, false, "") are written too; proto3 JSON leaves them out otherwise,

std::string ToJson(const google::protobuf::Message& m, bool with_zeros) {
  google::protobuf::util::JsonPrintOptions o;
  o.preserve_proto_field_names = true;  // the names specs are written with (supply_V, not supplyV)
  o.always_print_primitive_fields = with_zeros;
  std::string out;
  (void)google::protobuf::util::MessageToJsonString(m, &out, o);
  return out;
}

// A token fit for a cookie and a metadata value: printable, no separators.
bool TokenShapeOk(const std::string& t) {
  if (t.empty() || t.size() > 512) return false;
  return std::all_of(t.begin(), t.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || std::strchr("-._~+/=", c) != nullptr;
  });
}

std::string CookieToken(const httplib::Request& req) {
  const std::string cookies = req.get_header_value("Cookie");
  const std::string key = std::string(kCookie) + "=";
  size_t pos = 0;
  while (pos < cookies.size()) {
    while (pos < cookies.size() && (cookies[pos] == ' ' || cookies[pos] == ';')) ++pos;
    const size_t end = std::min(cookies.find(';', pos), cookies.size());
    if (cookies.compare(pos, key.size(), key) == 0) return cookies.substr(pos + key.size(), end - pos - key.size());
    pos = end;
  }
  return "";
}

// The caller's "authorization" value for the RPC: the Authorization header as sent, else (GET only) the cookie.
// Nothing at all when neither is there: the service answers UNAUTHENTICATED, as it does for gRPC callers.
// The header was checked by the door (Routes::Admit: visible ASCII only, what gRPC metadata may carry); it is

// A query parameter as a number; false (and a 400 naming it) when present but not a number.
bool NumberParam(const httplib::Request& req, httplib::Response& res, const char* name, double* out) {
  if (!req.has_param(name)) return true;
  const std::string v = req.get_param_value(name);
  try {
    size_t used = 0;
    const double d = std::stod(v, &used);
    if (used != v.size() || !std::isfinite(d)) throw std::invalid_argument(v);
    *out = d;
    return true;
  } catch (const std::exception&) {
    BadRequest(res, std::string(name) + ": not a number, got '" + v + "'");
    return false;
  }
}

bool IntParam(const httplib::Request& req, httplib::Response& res, const char* name, long long* out) {
  double d = static_cast<double>(*out);
  if (!NumberParam(req, res, name, &d)) return false;
  if (d != std::floor(d) || std::abs(d) > 9e15) {
    BadRequest(res, std::string(name) + ": not an integer, got '" + req.get_param_value(name) + "'");
    return false;
  }
  *out = static_cast<long long>(d);
  return true;
}

std::int64_t PathId(const httplib::Request& req) { return std::stoll(req.matches[1].str()); }

// A JSON body; false (and a 400) when it is not a JSON object.
bool BodyJson(const httplib::Request& req, httplib::Response& res, Json* out) {
  if (req.body.empty()) {
    *out = Json::object();
    return true;
  }
  if (!ValidUtf8(req.body)) {
    BadRequest(res, "body: not valid UTF-8");
    return false;
  }
  if (JsonDepth(req.body) > kMaxJsonDepth) {
    BadRequest(res, "body: JSON nested deeper than " + std::to_string(kMaxJsonDepth) + " levels");
    return false;
  }
  try {
    *out = Json::parse(req.body);
  } catch (const Json::exception& e) {
    BadRequest(res, std::string("body: not JSON: ") + e.what());
    return false;
  }
  if (!out->is_object()) {
    BadRequest(res, "body: must be a JSON object");
    return false;
  }
  return true;
}

void AppendNumber(std::string* out, double v) {
  if (std::isfinite(v)) {
    fmt::format_to(std::back_inserter(*out), "{:.10g}", v);
  } else {
    *out += "null";
  }
}

void SendClientError(httplib::Response& res, const grpc::Status& rpc, const Status& st) {
  if (!rpc.ok()) return SendError(res, rpc);
  SendError(res, ToGrpcStatus(st));
}

}  // namespace vb::web
