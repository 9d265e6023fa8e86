// The web door (web/door.h, docs/web.md "Door" and "Limits") against the real valvebench-server on loopback,
// with raw sockets so that the requests are sent byte for byte as an attacker would: every request of issue 24
// gets a 4xx JSON answer and the server stays up (a crash is a failure: the next request finds no server), heads
// and bodies are bounded whatever the framing, slow clients and many live views leave the page answering.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <httplib.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "tests/integration/server_process.h"
#include "valvebench/v1/api.grpc.pb.h"
#include "web/assets.h"
#include "web/gateway.h"
#include "web/head.h"
#include "service/service.h"

namespace {

using Json = nlohmann::json;
using Clock = std::chrono::steady_clock;
using vb::testing::kOperatorToken;
using vb::testing::kViewerToken;
// A POST's token and role are checked before its body is read (issue 34): the body checks need an operator.
const std::string kOperatorAuth = std::string("Authorization: Bearer ") + kOperatorToken + "\r\n";

int Connect(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<uint16_t>(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

bool SendAll(int fd, std::string_view data) {
  while (!data.empty()) {
    const ssize_t n = ::send(fd, data.data(), data.size(), MSG_NOSIGNAL);
    if (n <= 0) return false;
    data.remove_prefix(static_cast<size_t>(n));
  }
  return true;
}

// Reads until the peer closes, a whole answer (Content-Length) is in, or `timeout_s`.
std::string ReadAnswer(int fd, double timeout_s) {
  std::string in;
  const auto until = Clock::now() + std::chrono::milliseconds(static_cast<int>(timeout_s * 1000));
  for (;;) {
    const auto head_end = in.find("\r\n\r\n");
    if (head_end != std::string::npos) {
      const auto cl = in.find("Content-Length: ");
      if (cl != std::string::npos && cl < head_end) {
        const size_t len = std::stoul(in.substr(cl + 16));
        if (in.size() >= head_end + 4 + len) return in;
      }
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - Clock::now()).count();
    if (left <= 0) return in;
    pollfd p{fd, POLLIN, 0};
    if (poll(&p, 1, static_cast<int>(left)) <= 0) return in;
    char buf[65536];
    const ssize_t n = ::recv(fd, buf, sizeof(buf), 0);
    if (n <= 0) return in;
    in.append(buf, static_cast<size_t>(n));
  }
}

// Reads until the answer's head is in (for streams that do not end), or `timeout_s`.
std::string ReadHead(int fd, double timeout_s) {
  std::string in;
  const auto until = Clock::now() + std::chrono::milliseconds(static_cast<int>(timeout_s * 1000));
  while (in.find("\r\n\r\n") == std::string::npos) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - Clock::now()).count();
    if (left <= 0) break;
    pollfd p{fd, POLLIN, 0};
    if (poll(&p, 1, static_cast<int>(left)) <= 0) break;
    char buf[4096];
    const ssize_t n = ::recv(fd, buf, sizeof(buf), 0);
    if (n <= 0) break;
    in.append(buf, static_cast<size_t>(n));
  }
  return in;
}

int StatusOf(const std::string& answer) {
  if (answer.rfind("HTTP/1.1 ", 0) != 0) return 0;
  return std::stoi(answer.substr(9, 3));
}

Json BodyOf(const std::string& answer) {
  const auto at = answer.find("\r\n\r\n");
  if (at == std::string::npos) return nullptr;
  return Json::parse(answer.substr(at + 4), nullptr, false);
}

long RssKiB(int pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::stol(line.substr(6));
  return -1;
}

class WebDoorTest : public ::testing::Test {
 protected:
  void StartServer(const std::string& web_fields = "") {
    const std::string dir = ::testing::TempDir() + "/web-door-" +
                            ::testing::UnitTest::GetInstance()->current_test_info()->name();
    std::filesystem::remove_all(dir);
    server_ = std::make_unique<vb::testing::ServerProcess>(
        dir, R"("web": {"listen_address": "127.0.0.1:0")" + web_fields + "}");
    ASSERT_FALSE(server_->Start().empty()) << server_->Log();
    const auto until = Clock::now() + std::chrono::seconds(10);
    const std::string marker = "web dashboard on http://127.0.0.1:";
    while (Clock::now() < until) {
      const std::string log = server_->Log();
      const auto at = log.find(marker);
      if (at != std::string::npos) {
        port_ = std::stoi(log.substr(at + marker.size()));
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    ASSERT_GT(port_, 0) << server_->Log();
  }
  void SetUp() override { StartServer(); }

  // One request on a fresh connection, its answer.
  std::string Exchange(std::string_view request, double timeout_s = 5.0) {
    const int fd = Connect(port_);
    if (fd < 0) return "";
    SendAll(fd, request);
    std::string a = ReadAnswer(fd, timeout_s);
    ::close(fd);
    return a;
  }

  // The page and an API call both answer, and how long the slower took.
  double PageAnswers_s() {
    httplib::Client c("127.0.0.1", port_);
    c.set_connection_timeout(5, 0);
    c.set_read_timeout(5, 0);
    const auto t0 = Clock::now();
    auto page = c.Get("/");
    auto api = c.Get("/api/benches", {{"Authorization", std::string("Bearer ") + kViewerToken}});
    const double s = std::chrono::duration<double>(Clock::now() - t0).count();
    EXPECT_TRUE(page && page->status == 200);
    EXPECT_TRUE(api && api->status == 200) << (api ? api->body : "no answer");
    return (page && api && page->status == 200 && api->status == 200) ? s : 1e9;
  }

  void ExpectUp() {
    httplib::Client c("127.0.0.1", port_);
    auto res = c.Get("/api/benches", {{"Authorization", std::string("Bearer ") + kViewerToken}});
    ASSERT_TRUE(res) << "the server is gone:\n" << server_->Log().substr(0, 4000);
    EXPECT_EQ(res->status, 200);
  }

  std::unique_ptr<vb::testing::ServerProcess> server_;
  int port_ = 0;
};

// Issue 24's one-request crashes and the 'Low' list: a 4xx JSON answer each, and the server still up.
TEST_F(WebDoorTest, EveryRequestOfTheIssueGetsA4xxAndTheServerStaysUp) {
  struct Case {
    const char* what;
    std::string request;
    int status;
    const char* message;  // part of the JSON message
  };
  std::string deep(65000, '[');
  deep += std::string(65000, ']');
  const std::string deep_body = R"({"spec": )" + deep + "}";
  const std::string bad_utf8_body = "{\"spec\": {\"name\": \"a\xff\"}}";
  const std::vector<Case> cases = {
      {"C1: a TAB in the bearer token", "GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer a\tb\r\n\r\n",
       401, "visible ASCII"},
      {"C1: a non-ASCII byte in the token",
       "GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer caf\xc3\xa9\r\n\r\n", 401, "visible ASCII"},
      {"C1: invalid UTF-8 in the token", "GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer a\xff\r\n\r\n",
       400, "not valid UTF-8"},
      {"C1: a control character", "GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer a\x01z\r\n\r\n", 400,
       "control character"},
      {"C1: not a bearer token", "GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Basic eDp5\r\n\r\n", 401,
       "Bearer"},
      {"C2: invalid UTF-8 in the path (404 route)", "GET /%ff HTTP/1.1\r\nHost: x\r\n\r\n", 400, "path: not valid UTF-8"},
      {"invalid UTF-8 inside a route", "GET /api/runs/%ff HTTP/1.1\r\nHost: x\r\n\r\n", 400, "path: not valid UTF-8"},
      {"invalid UTF-8 in a query", "GET /api/runs?tag=%ff%fe HTTP/1.1\r\nHost: x\r\n\r\n", 400, "'tag': not valid UTF-8"},
      {"C3: JSON nested 65,000 deep",
       "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n" + kOperatorAuth + "Content-Length: " +
           std::to_string(deep_body.size()) + "\r\n\r\n" + deep_body,
       400, "nested deeper than 64"},
      {"invalid UTF-8 in a body",
       "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n" + kOperatorAuth + "Content-Length: " +
           std::to_string(bad_utf8_body.size()) + "\r\n\r\n" + bad_utf8_body,
       400, "body: not valid UTF-8"},
      {"a POST without Content-Length", "POST /api/logout HTTP/1.1\r\nHost: x\r\n\r\n", 411, "Content-Length: required"},
      {"a gzip body", "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Encoding: gzip\r\nContent-Length: 3\r\n\r\nabc",
       415, "Content-Encoding"},
      {"a Content-Length past the limit",
       "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Length: 99999999999\r\n\r\n", 413, "limit"},
      {"a negative Content-Length", "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Length: -1\r\n\r\n", 400,
       "Content-Length: not a number"},
      {"chunked and a Content-Length",
       "POST /api/runs HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\nContent-Length: 3\r\n\r\n0\r\n\r\n", 400,
       "Content-Length"},
      {"a JSON body that is not JSON",
       "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nAuthorization: Bearer " +
           std::string(kOperatorToken) + "\r\nContent-Length: 5\r\n\r\n{\"a\":",
       400, "body: not JSON"},
  };
  for (const Case& c : cases) {
    const std::string a = Exchange(c.request);
    EXPECT_EQ(StatusOf(a), c.status) << c.what << "\n" << a.substr(0, 600);
    const Json body = BodyOf(a);
    ASSERT_TRUE(body.is_object()) << c.what << "\n" << a.substr(0, 600);
    EXPECT_NE(body.value("message", "").find(c.message), std::string::npos) << c.what << ": " << body.dump();
    EXPECT_EQ(a.find("Content-Type: application/json"), a.find("Content-Type")) << c.what;
    ExpectUp();
  }
  // The token check never reaches gRPC metadata with a bad byte, and a good token still works.
  const std::string ok =
      Exchange("GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " + std::string(kViewerToken) + "\r\n\r\n");
  EXPECT_EQ(StatusOf(ok), 200) << ok.substr(0, 400);
}

// Raw-byte units: the checks themselves.
TEST(WebDoorChecks, Utf8DepthAndBearerTokens) {
  using vb::web::ValidUtf8;
  EXPECT_TRUE(ValidUtf8("plain ascii"));
  EXPECT_TRUE(ValidUtf8("caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80"));
  EXPECT_FALSE(ValidUtf8("\xff"));
  EXPECT_FALSE(ValidUtf8("\xc3"));              // cut short
  EXPECT_FALSE(ValidUtf8("\xc0\xaf"));          // overlong '/'
  EXPECT_FALSE(ValidUtf8("\xed\xa0\x80"));      // a UTF-16 surrogate
  EXPECT_FALSE(ValidUtf8("\xf4\x90\x80\x80"));  // past U+10FFFF
  EXPECT_EQ(vb::web::JsonDepth(R"({"a": [1, {"b": "[[[["}]})"), 3);
  EXPECT_EQ(vb::web::JsonDepth(R"("\"[[[")"), 0);
  std::string why;
  EXPECT_EQ(vb::web::BearerTokenOf("Bearer abc-1", &why), "abc-1");
  EXPECT_EQ(vb::web::BearerTokenOf("Bearer a\tb", &why), "");
  EXPECT_NE(why.find("visible ASCII"), std::string::npos);
  EXPECT_EQ(vb::web::BearerTokenOf("bearer abc", &why), "");
  EXPECT_EQ(vb::web::BearerTokenOf("Bearer ", &why), "");
}

// H1: a chunked body is bounded like any other; the head too, in size and time.
TEST_F(WebDoorTest, BodiesAndHeadsAreBoundedWhateverTheFraming) {
  const long rss0 = RssKiB(server_->pid());
  {
    // 64 MiB chunked (more than the 8 MiB limit): the server stops reading at the limit and answers 413.
    const int fd = Connect(port_);
    ASSERT_GE(fd, 0);
    SendAll(fd, "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n" + kOperatorAuth +
                    "Transfer-Encoding: chunked\r\n\r\n");
    std::atomic<bool> stop{false};
    std::thread sender([&] {
      const std::string chunk = "10000\r\n" + std::string(0x10000, ' ') + "\r\n";
      for (int k = 0; k < 1024 && !stop; ++k)
        if (!SendAll(fd, chunk)) break;
    });
    const std::string a = ReadAnswer(fd, 20);
    stop = true;
    ::shutdown(fd, SHUT_RDWR);
    sender.join();
    ::close(fd);
    EXPECT_EQ(StatusOf(a), 413) << a.substr(0, 400);
    EXPECT_NE(a.find("body: larger than the limit"), std::string::npos) << a.substr(0, 400);
  }
  {
    // 8 MiB of headers: refused at 64 KiB (431), nothing more is read.
    const int fd = Connect(port_);
    ASSERT_GE(fd, 0);
    std::string head = "GET / HTTP/1.1\r\nHost: x\r\n";
    for (int k = 0; head.size() < (8u << 20); ++k) head += "X-Filler-" + std::to_string(k) + ": " + std::string(200, 'a') + "\r\n";
    std::thread sender([&] { SendAll(fd, head); });
    const std::string a = ReadAnswer(fd, 20);
    ::shutdown(fd, SHUT_RDWR);
    sender.join();
    ::close(fd);
    EXPECT_EQ(StatusOf(a), 431) << a.substr(0, 400);
  }
  {
    // One request line of 8 MiB without a newline: the same.
    const int fd = Connect(port_);
    std::thread sender([&] { SendAll(fd, "GET /" + std::string(8u << 20, 'a')); });
    const std::string a = ReadAnswer(fd, 20);
    ::shutdown(fd, SHUT_RDWR);
    sender.join();
    ::close(fd);
    EXPECT_EQ(StatusOf(a), 431) << a.substr(0, 400);
  }
  ExpectUp();
  const long rss1 = RssKiB(server_->pid());
  RecordProperty("rss_growth_KiB", std::to_string(rss1 - rss0));
  // What was refused was never held: far below the 64 MiB sent (the issue saw +1.1 GB for 200 MB).
  EXPECT_LT(rss1 - rss0, 48 * 1024) << "RSS " << rss0 << " -> " << rss1 << " KiB";
}

// H2/M1: slow clients cost a file descriptor, not a worker: with 50 of them sending a header line every 1 s,
// the page still answers at once; each is closed (408) when its head is not in after head_timeout_s.
TEST_F(WebDoorTest, SlowClientsDoNotStopThePage) {
  server_.reset();
  StartServer(R"(, "head_timeout_s": 3)");
  std::vector<int> slow;
  for (int k = 0; k < 50; ++k) {
    const int fd = Connect(port_);
    ASSERT_GE(fd, 0);
    SendAll(fd, "GET /api/benches HTTP/1.1\r\nHost: x\r\n");
    slow.push_back(fd);
  }
  double worst_s = 0;
  for (int round = 0; round < 2; ++round) {
    std::this_thread::sleep_for(std::chrono::seconds(1));
    for (int fd : slow) SendAll(fd, "X-Slow: 1\r\n");
    worst_s = std::max(worst_s, PageAnswers_s());
  }
  std::cout << "page with 50 slow clients open: answered in " << worst_s * 1000 << " ms (worst of 2)\n";
  RecordProperty("page_ms_with_50_slow_clients", std::to_string(static_cast<int>(worst_s * 1000)));
  EXPECT_LT(worst_s, 1.0);
  // Past head_timeout_s (3 s here) every slow client has its 408 and its connection closed.
  std::this_thread::sleep_for(std::chrono::milliseconds(2500));
  int closed = 0;
  for (int fd : slow) {
    const std::string a = ReadAnswer(fd, 2.0);
    closed += StatusOf(a) == 408;
    ::close(fd);
  }
  EXPECT_EQ(closed, 50);
  ExpectUp();
}

// A complete head, then a body trickled in a byte a second: the worker it holds is let go (408) once the body
// falls behind the minimum rate after its grace (10 s), well before the 60 s cap.
TEST_F(WebDoorTest, ATrickledBodyIsCutOffByItsMinimumRate) {
  const int fd = Connect(port_);
  ASSERT_GE(fd, 0);
  SendAll(fd, "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n" + kOperatorAuth +
                    "Content-Length: 1000\r\n\r\n{");
  std::string a;
  const auto t0 = Clock::now();
  while (a.empty() && Clock::now() - t0 < std::chrono::seconds(40)) {
    SendAll(fd, " ");
    a = ReadAnswer(fd, 1.0);
  }
  ::close(fd);
  const double s = std::chrono::duration<double>(Clock::now() - t0).count();
  std::cout << "trickled body answered after " << s << " s\n";
  EXPECT_EQ(StatusOf(a), 408) << a.substr(0, 300);
  EXPECT_NE(a.find("body: not received in time"), std::string::npos) << a.substr(0, 300);
  EXPECT_LT(s, 30.0);  // the rate rule, not the 60 s cap
  ExpectUp();
}

// H2/M1: live views are capped per session and in all (429 beyond), so 200 attempted streams leave workers for
// the page, which still answers at once.
TEST_F(WebDoorTest, ManyLiveViewsLeaveThePageAnswering) {
  httplib::Client c("127.0.0.1", port_);
  std::ifstream in(std::string(VB_SOURCE_DIR) + "/examples/standard/e3.json");
  std::stringstream ss;
  ss << in.rdbuf();
  Json spec = Json::parse(ss.str());
  spec["realtime"] = true;
  spec["duration_s"] = 30;
  auto sub = c.Post("/api/runs", {{"Authorization", std::string("Bearer ") + kOperatorToken}},
                    R"({"spec": )" + spec.dump() + "}", "application/json");
  ASSERT_TRUE(sub && sub->status == 201) << (sub ? sub->body : "");
  const std::string id = Json::parse(sub->body)["run_ids"][0].get<std::string>();
  std::vector<int> streams;
  int open = 0, refused = 0;
  const char* tokens[] = {kViewerToken, kOperatorToken, vb::testing::kOperator2Token, vb::testing::kAdminToken};
  // One after another, as tabs open: a refused one's connection is closed by the server (and here).
  for (int k = 0; k < 200; ++k) {
    const int fd = Connect(port_);
    ASSERT_GE(fd, 0);
    SendAll(fd, "GET /api/runs/" + id + "/events?rate_Hz=10 HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " +
                    tokens[k % 4] + "\r\n\r\n");
    const int st = StatusOf(ReadHead(fd, 5.0));
    if (st == 200) {
      ++open;
      streams.push_back(fd);
    } else {
      refused += st == 429;
      ::close(fd);
    }
  }
  const double page_s = PageAnswers_s();
  std::cout << "200 live views asked: " << open << " open, " << refused << " refused (429); page answered in "
            << page_s * 1000 << " ms\n";
  RecordProperty("page_ms_with_200_streams", std::to_string(static_cast<int>(page_s * 1000)));
  EXPECT_EQ(open, 4 * 8);  // max_streams_per_session 8, four sessions (the total cap, 48, is not reached)
  EXPECT_EQ(refused, 200 - 4 * 8);
  EXPECT_LT(page_s, 1.0);
  for (int fd : streams) ::close(fd);
  c.Post("/api/runs/" + id + "/cancel", {{"Authorization", std::string("Bearer ") + kOperatorToken}}, "{}",
         "application/json");
  ExpectUp();
}

// The total cap on live views, below the per-session ones: with max_streams 10, four sessions share ten.
TEST_F(WebDoorTest, LiveViewsAreCappedInAll) {
  server_.reset();
  StartServer(R"(, "max_streams": 10)");
  httplib::Client c("127.0.0.1", port_);
  std::ifstream in(std::string(VB_SOURCE_DIR) + "/examples/standard/e3.json");
  std::stringstream ss;
  ss << in.rdbuf();
  Json spec = Json::parse(ss.str());
  spec["realtime"] = true;
  spec["duration_s"] = 30;
  auto sub = c.Post("/api/runs", {{"Authorization", std::string("Bearer ") + kOperatorToken}},
                    R"({"spec": )" + spec.dump() + "}", "application/json");
  ASSERT_TRUE(sub && sub->status == 201) << (sub ? sub->body : "");
  const std::string id = Json::parse(sub->body)["run_ids"][0].get<std::string>();
  const char* tokens[] = {kViewerToken, kOperatorToken, vb::testing::kOperator2Token, vb::testing::kAdminToken};
  std::vector<int> open_fds;
  int refused = 0;
  for (int k = 0; k < 20; ++k) {
    const int fd = Connect(port_);
    ASSERT_GE(fd, 0);
    SendAll(fd, "GET /api/runs/" + id + "/events?rate_Hz=10 HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " +
                    tokens[k % 4] + "\r\n\r\n");
    const std::string a = ReadHead(fd, 5.0);
    if (StatusOf(a) == 200) {
      open_fds.push_back(fd);
    } else {
      refused += StatusOf(a) == 429;
      ::close(fd);
    }
  }
  EXPECT_EQ(open_fds.size(), 10u);
  EXPECT_EQ(refused, 10);
  // A stream that ends gives its place back.
  ::close(open_fds.back());
  open_fds.pop_back();
  bool again = false;
  for (int attempt = 0; attempt < 50 && !again; ++attempt) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const int fd = Connect(port_);
    SendAll(fd, "GET /api/runs/" + id + "/events?rate_Hz=10 HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " +
                    std::string(kViewerToken) + "\r\n\r\n");
    again = StatusOf(ReadHead(fd, 5.0)) == 200;
    if (again) open_fds.push_back(fd); else ::close(fd);
  }
  EXPECT_TRUE(again) << "a closed stream's place was not given back";
  for (int fd : open_fds) ::close(fd);
  c.Post("/api/runs/" + id + "/cancel", {{"Authorization", std::string("Bearer ") + kOperatorToken}}, "{}",
         "application/json");
  ExpectUp();
}

// The request path without sockets (the fuzz target's way in) answers the issue's requests too.
TEST(WebRawGateway, AnswersWithoutASocket) {
  auto channel = grpc::CreateChannel("127.0.0.1:1", grpc::InsecureChannelCredentials());
  vb::web::RawGateway g(channel);
  const std::string a = g.Serve("GET /%ff HTTP/1.1\r\nHost: x\r\n\r\nGET /api/benches HTTP/1.1\r\nHost: x\r\n"
                                "Authorization: Bearer a\tb\r\n\r\n");
  EXPECT_EQ(a.rfind("HTTP/1.1 400", 0), 0u) << a;
  EXPECT_NE(a.find("HTTP/1.1 401"), std::string::npos) << a;
}


// Issue 34 (critical): a Range of many ranges builds no multipart answer, GET or HEAD, with or without a token;
// one range is still served (206). Before: 2,700 ranges of "0-" on the dygraph asset built a 354 MB answer.
TEST_F(WebDoorTest, ManyRangesGetTheWholeAnswerOnce) {
  const vb::web::Asset* asset = vb::web::FindAsset("/dygraph.min.js");
  ASSERT_NE(asset, nullptr);
  const long rss0 = RssKiB(server_->pid());
  std::string ranges = "bytes=0-";
  for (int k = 1; k < 2700; ++k) ranges += ",0-";
  for (int round = 0; round < 3; ++round) {
    for (const char* method : {"GET", "HEAD"}) {
      const int fd = Connect(port_);
      ASSERT_GE(fd, 0);
      SendAll(fd, std::string(method) + " /dygraph.min.js HTTP/1.1\r\nHost: x\r\nRange: " + ranges + "\r\n\r\n");
      const std::string a = std::string(method) == "GET" ? ReadAnswer(fd, 10.0) : ReadHead(fd, 10.0);
      ::close(fd);
      EXPECT_EQ(StatusOf(a), 200) << method << "\n" << a.substr(0, 400);
      EXPECT_EQ(a.find("multipart/byteranges"), std::string::npos) << method;
      EXPECT_NE(a.find("Content-Length: " + std::to_string(asset->size) + "\r\n"), std::string::npos)
          << method << "\n" << a.substr(0, 400);
    }
  }
  // Two Range lines, and a 60 KB Range (20,000 ranges: cpp-httplib's std::regex would have walked it all).
  std::string huge = "bytes=0-0";
  while (huge.size() < 60000) huge += ",1-1";
  for (const std::string& head : {std::string("Range: bytes=0-9\r\nRange: bytes=0-9\r\n"), "Range: " + huge + "\r\n"}) {
    const std::string a = Exchange("GET /dygraph.min.js HTTP/1.1\r\nHost: x\r\n" + head + "\r\n", 10.0);
    EXPECT_EQ(StatusOf(a), 200) << a.substr(0, 300);
  }
  // A JSON answer with a viewer token, many ranges: the whole JSON once.
  std::string api_ranges = "bytes=0-";
  for (int k = 1; k < 300; ++k) api_ranges += ",0-";
  const std::string api = Exchange("GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " +
                                   std::string(kViewerToken) + "\r\nRange: " + api_ranges + "\r\n\r\n");
  EXPECT_EQ(StatusOf(api), 200) << api.substr(0, 300);
  EXPECT_TRUE(BodyOf(api).is_object()) << api.substr(0, 300);
  // One range: served as asked (a resumed download).
  const std::string one = Exchange("GET /dygraph.min.js HTTP/1.1\r\nHost: x\r\nRange: bytes=10-19\r\n\r\n");
  EXPECT_EQ(StatusOf(one), 206) << one.substr(0, 300);
  EXPECT_NE(one.find("Content-Range: bytes 10-19/" + std::to_string(asset->size)), std::string::npos) << one.substr(0, 300);
  EXPECT_NE(one.find("Content-Length: 10\r\n"), std::string::npos);
  const long rss1 = RssKiB(server_->pid());
  // 6 answers of 2,700 copies would be 6 x 2,700 x the asset (> 1 GB); the whole asset once is ~0.1 MB each.
  EXPECT_LT(rss1 - rss0, 32 * 1024) << "RSS grew from " << rss0 << " to " << rss1 << " KiB";
  ExpectUp();
}

// Issue 34 (medium): framing a keep-alive proxy and cpp-httplib would read differently is refused (400) before
// cpp-httplib parses it; a GET's body is never taken for the next request.
TEST_F(WebDoorTest, AmbiguousFramingIsRefused) {
  const std::string good = "Authorization: Bearer " + std::string(kViewerToken) + "\r\n";
  struct Case {
    const char* what;
    std::string request;
    const char* message;
  };
  const std::vector<Case> cases = {
      {"a %-escaped Content-Length", "POST /api/logout HTTP/1.1\r\nHost: x\r\nContent-Length: %32\r\n\r\n{}",
       "Content-Length: not a number"},
      {"a %-escaped Transfer-Encoding",
       "POST /api/logout HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: %63hunked\r\n\r\n0\r\n\r\n", "%-escapes"},
      {"a GET with a body", "GET /api/benches HTTP/1.1\r\nHost: x\r\nContent-Length: 40\r\n\r\n"
                            "GET /api/benches HTTP/1.1\r\nHost: x\r\n\r\n", "has no body"},
      {"a HEAD with a chunked body", "HEAD / HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n0\r\n\r\n",
       "has no body"},
      {"a header name with a space", "GET /api/benches HTTP/1.1\r\nHost: x\r\nContent-Length : 5\r\n\r\n",
       "not a token"},
      {"a folded header", "GET /api/benches HTTP/1.1\r\nHost: x\r\nX-A: 1\r\n  folded\r\n\r\n", "obs-fold"},
      {"a bare LF inside the head", "GET /api/benches HTTP/1.1\r\nHost: x\nContent-Length: 5\r\n\r\n", "bare CR or LF"},
      {"no Host on HTTP/1.1", "GET /api/benches HTTP/1.1\r\n" + good + "\r\n", "Host: required"},
      {"two Hosts", "GET /api/benches HTTP/1.1\r\nHost: x\r\nHost: y\r\n\r\n", "Host: sent more than once"},
      {"HTTP/1.2", "GET /api/benches HTTP/1.2\r\nHost: x\r\n\r\n", "version"},
  };
  for (const Case& c : cases) {
    const std::string a = Exchange(c.request);
    EXPECT_EQ(StatusOf(a), 400) << c.what << "\n" << a.substr(0, 600);
    EXPECT_NE(BodyOf(a).value("message", "").find(c.message), std::string::npos) << c.what << ": " << a.substr(0, 600);
    EXPECT_NE(a.find("Connection: close"), std::string::npos) << c.what;
  }
  // HTTP/1.0 without Host, and a GET with Content-Length: 0, are fine.
  EXPECT_EQ(StatusOf(Exchange("GET /api/benches HTTP/1.0\r\n" + good + "\r\n")), 200);
  EXPECT_EQ(StatusOf(Exchange("GET /api/benches HTTP/1.1\r\nHost: x\r\nContent-Length: 0\r\n" + good + "\r\n")), 200);
  ExpectUp();
}

TEST(WebDoorChecks, FilterHeadKeepsOneRangeAndTheBytesAfterTheHead) {
  using vb::web::FilterHead;
  EXPECT_TRUE(vb::web::SingleByteRange("bytes=0-9"));
  EXPECT_TRUE(vb::web::SingleByteRange("bytes=5-"));
  EXPECT_TRUE(vb::web::SingleByteRange("bytes=-5"));
  EXPECT_FALSE(vb::web::SingleByteRange("bytes=0-1,2-3"));
  EXPECT_FALSE(vb::web::SingleByteRange("bytes=9-0"));
  EXPECT_FALSE(vb::web::SingleByteRange("bytes=-"));
  EXPECT_FALSE(vb::web::SingleByteRange("items=0-1"));
  std::string a = "GET / HTTP/1.1\r\nHost: x\r\nRange: bytes=0-,0-\r\nX: y\r\n\r\nNEXT";
  auto v = FilterHead(&a);
  EXPECT_EQ(v.status, 0);
  EXPECT_EQ(v.ranges_dropped, 1);
  EXPECT_EQ(a, "GET / HTTP/1.1\r\nHost: x\r\nX: y\r\n\r\nNEXT");
  std::string b = "\r\nGET / HTTP/1.1\r\nHost: x\r\nrange: bytes=3-4\r\n\r\n";
  v = FilterHead(&b);
  EXPECT_EQ(v.status, 0);
  EXPECT_EQ(v.ranges_dropped, 0);
  EXPECT_EQ(b, "GET / HTTP/1.1\r\nHost: x\r\nrange: bytes=3-4\r\n\r\n");
  std::string c = "GET / HTTP/1.1\r\nHost: x\r\nContent-Length: +1\r\n\r\n";
  EXPECT_EQ(FilterHead(&c).status, 400);
}


// Issue 34 (high): an import's token and role are checked before its body is read (8 MB announced, none sent:
// the answer comes at once, or this test would wait for the body and read nothing); a data file's header is
// checked in linear time with a cap on its columns, before a byte is written.
TEST_F(WebDoorTest, ImportChecksTheTokenBeforeTheBodyAndCapsTheColumns) {
  struct Who {
    std::string header;
    int status;
  };
  const std::vector<Who> who = {{"", 401},
                                {"Authorization: Bearer wrong-token\r\n", 401},
                                {"Authorization: Bearer " + std::string(kViewerToken) + "\r\n", 403}};
  for (const Who& w : who) {
    const int fd = Connect(port_);
    ASSERT_GE(fd, 0);
    SendAll(fd, "POST /api/import HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n" + w.header +
                    "Content-Length: 8000000\r\n\r\n{");
    const std::string a = ReadAnswer(fd, 5.0);
    ::close(fd);
    EXPECT_EQ(StatusOf(a), w.status) << w.header << "\n" << a.substr(0, 400);
    EXPECT_NE(a.find("Connection: close"), std::string::npos) << a.substr(0, 400);
  }
  httplib::Client c("127.0.0.1", port_);
  c.set_read_timeout(20, 0);
  std::string header = "t_s,gate,i_A";
  for (int k = 0; k < 100000; ++k) header += ",c" + std::to_string(k);
  auto wide = c.Post("/api/import", {{"Authorization", std::string("Bearer ") + kOperatorToken}},
                     Json{{"dataset", "d1"}, {"files", {{"manifest.json", "{}"}, {"a.csv", header + "\n"}}}}.dump(),
                     "application/json");
  ASSERT_TRUE(wide);
  EXPECT_EQ(wide->status, 400) << wide->body.substr(0, 300);
  EXPECT_NE(wide->body.find("d1/a.csv:1: more than 256 columns"), std::string::npos) << wide->body.substr(0, 300);
  auto twice = c.Post("/api/import", {{"Authorization", std::string("Bearer ") + kOperatorToken}},
                      Json{{"dataset", "d1"}, {"files", {{"manifest.json", "{}"}, {"a.csv", "t_s,gate,i_A,gate\n"}}}}.dump(),
                      "application/json");
  ASSERT_TRUE(twice);
  EXPECT_EQ(twice->status, 400);
  EXPECT_NE(twice->body.find("d1/a.csv:1: column gate appears twice"), std::string::npos) << twice->body;
  ExpectUp();
}

// A client that sends its whole upload before it reads (cpp-httplib's, curl's for small bodies, a script's) must
// get the refusal, not a reset: the door answers before the body and then lingers, discarding the body, until
// the client closes (web/door.cc, Door::Linger). Closing with the body unread made the kernel send RST, which
// could reach the client before it read the 403 (CI lost WebGatewayTest.SessionDownloadsAndImport's this way).
TEST_F(WebDoorTest, ARefusedUploadSentWholeStillGetsItsAnswer) {
  // Larger than loopback's socket buffers hold (about 4 + 6 MiB at most), under the 8 MiB body limit: the
  // answer comes while the client is still sending.
  const std::string body((15 << 20) / 2, 'x');
  for (int k = 0; k < 4; ++k) {
    const int fd = Connect(port_);
    ASSERT_GE(fd, 0);
    const bool sent = SendAll(fd, "POST /api/import HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                                  "Authorization: Bearer " + std::string(kViewerToken) + "\r\n"
                                  "Content-Length: " + std::to_string(body.size()) + "\r\n\r\n" + body);
    const std::string a = ReadAnswer(fd, 5.0);
    ::close(fd);
    EXPECT_TRUE(sent) << "attempt " << k << ": the upload was cut off by a reset";
    EXPECT_EQ(StatusOf(a), 403) << "attempt " << k << ":\n" << a.substr(0, 400);
  }
  ExpectUp();
}

TEST(WebDoorChecks, CsvHeaderProblemIsLinearAndCapped) {
  EXPECT_EQ(vb::web::CsvHeaderProblem("t_s,gate,i_A\n0,1,2\n"), "");
  EXPECT_EQ(vb::web::CsvHeaderProblem("\xEF\xBB\xBFt_s,i_A\r\n"), "");
  EXPECT_NE(vb::web::CsvHeaderProblem("t_s,i_A,t_s\n").find("column t_s appears twice"), std::string::npos);
  std::string wide = "t_s";
  for (size_t k = 1; k < vb::web::kMaxCsvColumns; ++k) wide += ",c" + std::to_string(k);
  EXPECT_EQ(vb::web::CsvHeaderProblem(wide), "");  // exactly the cap
  EXPECT_NE(vb::web::CsvHeaderProblem(wide + ",one_more").find("more than 256 columns"), std::string::npos);
}

// Issue 34: uploads a killed server left in the temporary folder are removed when a server starts; another
// running server's (its process alive) are left alone.
class WebDoorStartTest : public WebDoorTest {
 protected:
  void SetUp() override {}
};
TEST_F(WebDoorStartTest, StaleImportUploadsAreRemovedAtStart) {
  // A temporary directory of this test's own (TMPDIR for the server it starts): other tests' servers, started
  // meanwhile under ctest -j, clean the shared /tmp at their start too, and one of them could take the stale
  // directory first.
  const std::filesystem::path tmp = std::filesystem::path(::testing::TempDir()) / "vb-stale-import-tmp";
  std::filesystem::remove_all(tmp);
  std::filesystem::create_directories(tmp);
  ::setenv("TMPDIR", tmp.c_str(), 1);
  // pid 999999999 is past any pid_max (4,194,304 at most): no such process.
  const auto stale = tmp / "valvebench-import-999999999-abc123";
  const auto live = tmp / ("valvebench-import-" + std::to_string(::getpid()) + "-abc123");
  std::filesystem::create_directories(stale / "d1");
  std::ofstream(stale / "d1" / "a.csv") << "t_s,gate,i_A\n";
  std::filesystem::create_directories(live);
  StartServer();
  ::unsetenv("TMPDIR");
  EXPECT_FALSE(std::filesystem::exists(stale)) << server_->Log();
  EXPECT_TRUE(std::filesystem::exists(live));
  EXPECT_NE(server_->Log().find("removed 1 temporary import directory"), std::string::npos) << server_->Log();
  std::filesystem::remove_all(live);
}

// Issue 34 (high): SIGTERM stops the benches to their safe state first, then drains the doors within a bound:
// with a run on a bench, slow imports trickling their bodies and a live view open, the benches are stopped
// before the doors close and the process has exited within 5 s (the unit's TimeoutStopSec is 15 s). Before,
// main joined the door's workers first: 45 s, once more than 95 s.
TEST_F(WebDoorTest, SigtermStopsTheBenchesFirstAndExitsWithinFiveSeconds) {
  httplib::Client c("127.0.0.1", port_);
  std::ifstream in(std::string(VB_SOURCE_DIR) + "/examples/standard/e3.json");
  std::stringstream ss;
  ss << in.rdbuf();
  Json spec = Json::parse(ss.str());
  spec["realtime"] = true;
  spec["duration_s"] = 30;
  auto sub = c.Post("/api/runs", {{"Authorization", std::string("Bearer ") + kOperatorToken}},
                    R"({"spec": )" + spec.dump() + "}", "application/json");
  ASSERT_TRUE(sub && sub->status == 201) << (sub ? sub->body : "");
  const std::string id = Json::parse(sub->body)["run_ids"][0].get<std::string>();
  // Slow imports: a complete head with an operator's token, then a body a few bytes at a time.
  std::vector<int> fds;
  for (int k = 0; k < 8; ++k) {
    const int fd = Connect(port_);
    ASSERT_GE(fd, 0);
    SendAll(fd, "POST /api/import HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n" + kOperatorAuth +
                    "Content-Length: 4000000\r\n\r\n{\"dataset\": \"d1\", \"files\": {\"a.csv\": \"");
    fds.push_back(fd);
  }
  const int live = Connect(port_);
  SendAll(live, "GET /api/runs/" + id + "/events?rate_Hz=10 HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " +
                    std::string(kViewerToken) + "\r\n\r\n");
  ASSERT_EQ(StatusOf(ReadHead(live, 5.0)), 200);
  fds.push_back(live);
  std::atomic<bool> stop{false};
  std::thread trickle([&] {
    while (!stop) {
      for (size_t k = 0; k + 1 < fds.size(); ++k) SendAll(fds[k], "t_s,gate,i_A\\n");
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
  });
  std::this_thread::sleep_for(std::chrono::seconds(1));  // the run is running, the uploads are in flight
  const auto t0 = Clock::now();
  const int status = server_->Kill(SIGTERM);
  const double s = std::chrono::duration<double>(Clock::now() - t0).count();
  stop = true;
  trickle.join();
  for (int fd : fds) ::close(fd);
  std::cout << "SIGTERM with 8 slow imports and a live view: exited after " << s << " s\n";
  RecordProperty("sigterm_exit_ms", std::to_string(static_cast<int>(s * 1000)));
  const std::string log = server_->Log();
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << log;
  EXPECT_LT(s, 5.0) << log;
  const auto benches = log.find("benches stopped (safe state)");
  ASSERT_NE(benches, std::string::npos) << log;
  const auto doors = log.find("doors closed");
  if (doors != std::string::npos) {
    EXPECT_LT(benches, doors);
  }
}


// Issue 34 (high): the open-file limit is raised to the hard limit at start, so 1,100 idle TCP connections to
// the gRPC port (no bytes, no token) do not reach EMFILE, after which gRPC 1.51's listener never accepts again.
// The server is started with a soft limit of 1,024 (a shell's default).
int ConnectFrom(uint32_t from_host, int port);
int OpenFds(int pid);

bool GrpcAnswers(const std::string& addr) {
  auto stub = valvebench::v1::BenchService::NewStub(grpc::CreateChannel(addr, grpc::InsecureChannelCredentials()));
  grpc::ClientContext ctx;
  ctx.AddMetadata("authorization", std::string("Bearer ") + kViewerToken);
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  valvebench::v1::ListBenchesResponse out;
  const grpc::Status st = stub->ListBenches(&ctx, valvebench::v1::ListBenchesRequest(), &out);
  return st.ok() && out.benches_size() == 2;
}

// Issue 34: 1,100 idle TCP connections and gRPC never answered again (its accept loop gives up at its first
// EMFILE). The server's own listener (server/grpc_listener.h) caps one address's connections, and survives running
// out of descriptors: with its soft limit lowered under it (prlimit) until accepts fail, gRPC answers again once
// the idle connections are gone.
TEST_F(WebDoorStartTest, ManyIdleGrpcConnectionsLeaveGrpcAnswering) {
  rlimit was{};
  ASSERT_EQ(getrlimit(RLIMIT_NOFILE, &was), 0);
  if (was.rlim_max < 4096) GTEST_SKIP() << "hard open-file limit " << was.rlim_max << " < 4096";
  if (was.rlim_cur < 2048) {
    rlimit mine = was;
    mine.rlim_cur = std::min<rlim_t>(was.rlim_max, 4096);
    ASSERT_EQ(setrlimit(RLIMIT_NOFILE, &mine), 0);
    was = mine;
  }
  rlimit low = was;
  low.rlim_cur = 1024;
  ASSERT_EQ(setrlimit(RLIMIT_NOFILE, &low), 0);
  StartServer();
  ASSERT_EQ(setrlimit(RLIMIT_NOFILE, &was), 0);
  EXPECT_NE(server_->Log().find("open files: limit raised from 1024"), std::string::npos) << server_->Log();
  const std::string addr = server_->address();
  const int grpc_port = std::stoi(addr.substr(addr.rfind(':') + 1));

  // One address: 300 connections, 256 kept, the rest closed at once; another address is answered.
  std::vector<int> idle;
  for (int k = 0; k < 300; ++k)
    if (const int fd = ConnectFrom(0x7f000002, grpc_port); fd >= 0) idle.push_back(fd);
  EXPECT_EQ(idle.size(), 300u);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  EXPECT_NE(server_->Log().find("closed: that address has 256 gRPC connections open"), std::string::npos)
      << server_->Log().substr(0, 3000);
  EXPECT_TRUE(GrpcAnswers(addr)) << server_->Log().substr(0, 3000);

  // Out of descriptors: the server's soft limit lowered to what it has open plus 40, then 200 more idle
  // connections from five addresses.
  const int pid = server_->pid();
  rlimit server_was{};
  ASSERT_EQ(prlimit(pid, RLIMIT_NOFILE, nullptr, &server_was), 0);
  rlimit tight = server_was;
  tight.rlim_cur = static_cast<rlim_t>(OpenFds(pid) + 40);
  ASSERT_EQ(prlimit(pid, RLIMIT_NOFILE, &tight, nullptr), 0);
  for (int k = 0; k < 200; ++k)
    if (const int fd = ConnectFrom(0x7f000003 + static_cast<uint32_t>(k % 5), grpc_port); fd >= 0) idle.push_back(fd);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  EXPECT_NE(server_->Log().find("grpc: out of file descriptors"), std::string::npos) << server_->Log().substr(0, 3000);
  for (int fd : idle) ::close(fd);
  ASSERT_EQ(prlimit(pid, RLIMIT_NOFILE, &server_was, nullptr), 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  EXPECT_TRUE(GrpcAnswers(addr)) << "the listener survived EMFILE\n" << server_->Log().substr(0, 3000);
  ExpectUp();
}

int OpenFds(int pid) {
  int n = 0;
  for (const auto& e : std::filesystem::directory_iterator("/proc/" + std::to_string(pid) + "/fd")) {
    (void)e;
    ++n;
  }
  return n;
}

// What the open files are (for a failure's message): link target kinds and counts.
std::string FdKinds(int pid) {
  std::map<std::string, int> kinds;
  for (const auto& e : std::filesystem::directory_iterator("/proc/" + std::to_string(pid) + "/fd")) {
    std::error_code ec;
    std::string t = std::filesystem::read_symlink(e.path(), ec).string();
    if (const auto colon = t.find(":["); colon != std::string::npos) t = t.substr(0, colon);
    ++kinds[t];
  }
  std::string out;
  for (const auto& [k, n] : kinds) out += k + " x" + std::to_string(n) + "; ";
  return out;
}

// Issue 34 (high): gRPC server streams are capped per user (64) and in all (96), RESOURCE_EXHAUSTED beyond,
// and a closed stream's place comes back (the pool itself: ServiceStorePool). Before: 1,000 viewer
// WatchRun streams left 913 threads and 1,650 SQLite connections until restart.
TEST_F(WebDoorTest, GrpcStreamsAreCappedPerUserAndTheirPlacesComeBack) {
  httplib::Client c("127.0.0.1", port_);
  std::ifstream in(std::string(VB_SOURCE_DIR) + "/examples/standard/e3.json");
  std::stringstream ss;
  ss << in.rdbuf();
  Json spec = Json::parse(ss.str());
  spec["realtime"] = true;
  spec["duration_s"] = 30;
  auto sub = c.Post("/api/runs", {{"Authorization", std::string("Bearer ") + kOperatorToken}},
                    R"({"spec": )" + spec.dump() + "}", "application/json");
  ASSERT_TRUE(sub && sub->status == 201) << (sub ? sub->body : "");
  const long long id = std::stoll(Json::parse(sub->body)["run_ids"][0].get<std::string>());
  auto channel = grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials());
  auto stub = valvebench::v1::BenchService::NewStub(channel);
  ASSERT_TRUE(channel->WaitForConnected(std::chrono::system_clock::now() + std::chrono::seconds(5)));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const int fds0 = OpenFds(server_->pid());
  struct Watch {
    grpc::ClientContext ctx;
    std::unique_ptr<grpc::ClientReader<valvebench::v1::RunEvent>> reader;
  };
  std::vector<std::unique_ptr<Watch>> open;
  int refused = 0;
  std::string message;
  for (int k = 0; k < 66; ++k) {
    auto w = std::make_unique<Watch>();
    w->ctx.AddMetadata("authorization", std::string("Bearer ") + kViewerToken);
    valvebench::v1::WatchRunRequest r;
    r.set_run_id(id);
    w->reader = stub->WatchRun(&w->ctx, r);
    valvebench::v1::RunEvent ev;
    if (w->reader->Read(&ev)) {
      open.push_back(std::move(w));
    } else {
      const grpc::Status st = w->reader->Finish();
      refused += st.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED;
      message = st.error_message();
    }
  }
  const int fds_open = OpenFds(server_->pid());
  std::cout << "66 WatchRun streams of one viewer: " << open.size() << " open, " << refused
            << " refused; server fds " << fds0 << " -> " << fds_open << "\n";
  EXPECT_EQ(open.size(), 64u);
  EXPECT_EQ(refused, 2);
  EXPECT_NE(message.find("WatchRun: user viewer has 64 streams open"), std::string::npos) << message;
  for (auto& w : open) w->ctx.TryCancel();
  for (auto& w : open) (void)w->reader->Finish();
  open.clear();
  // A closed stream's place comes back.
  valvebench::v1::WatchRunRequest r;
  r.set_run_id(id);
  bool again = false;
  for (int k = 0; k < 50 && !again; ++k) {
    auto w2 = std::make_unique<Watch>();
    w2->ctx.AddMetadata("authorization", std::string("Bearer ") + kViewerToken);
    w2->reader = stub->WatchRun(&w2->ctx, r);
    valvebench::v1::RunEvent ev;
    again = w2->reader->Read(&ev);
    w2->ctx.TryCancel();
    (void)w2->reader->Finish();
    if (!again) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_TRUE(again);
  // The pool closed the streams' connections but 8; SQLite itself keeps a closed connection's descriptor while
  // other connections hold locks on the file and reuses it for the next open (unix VFS), so the count is
  // bounded by the caps, not back to where it was.
  std::cout << "after the streams ended: server fds " << OpenFds(server_->pid()) << ": " << FdKinds(server_->pid())
            << "\n";
  c.Post("/api/runs/" + std::to_string(id) + "/cancel", {{"Authorization", std::string("Bearer ") + kOperatorToken}},
         "{}", "application/json");
  ExpectUp();
}


TEST(WebDoorChecks, ReportCspAllowsItsInlineScriptsByHash) {
  // sha256("abc") = ungWv48Bz+pBQUDeXa4iI7ADYaOWF3qctBD/YfIAFa0= (base64)
  const std::string csp = vb::web::ReportCsp("<script>abc</script><script type=\"application/json\">{}</script>");
  EXPECT_NE(csp.find("script-src 'sha256-ungWv48Bz+pBQUDeXa4iI7ADYaOWF3qctBD/YfIAFa0=';"), std::string::npos) << csp;
  EXPECT_EQ(csp.find("'unsafe-inline'; img"), csp.find("'unsafe-inline'"));  // only styles inline
  EXPECT_NE(vb::web::ReportCsp("<p>no script</p>").find("script-src 'none'"), std::string::npos);
}

TEST(WebDoorChecks, AcceptEncodingBecomesGzipOrNothing) {
  std::string a = "GET / HTTP/1.1\r\nHost: x\r\nAccept-Encoding: gzip, deflate, br\r\n\r\n";
  EXPECT_TRUE(vb::web::FilterHead(&a).encoding_rewritten);
  EXPECT_EQ(a, "GET / HTTP/1.1\r\nHost: x\r\nAccept-Encoding: gzip\r\n\r\n");
  std::string b = "GET / HTTP/1.1\r\nHost: x\r\nAccept-Encoding: br\r\n\r\n";
  EXPECT_TRUE(vb::web::FilterHead(&b).encoding_rewritten);
  EXPECT_EQ(b, "GET / HTTP/1.1\r\nHost: x\r\n\r\n");
  std::string c = "GET / HTTP/1.1\r\nHost: x\r\nAccept-Encoding: gzip\r\n\r\n";
  EXPECT_FALSE(vb::web::FilterHead(&c).encoding_rewritten);
}


// Issue 34 (medium/low): never brotli (quality 11 cost 0.21 s of CPU per asset request), gzip when asked; a
// request followed by a half-close is answered.
TEST_F(WebDoorTest, GzipNotBrotliAndAHalfClosedRequestIsAnswered) {
  const std::string br = Exchange("GET /app.js HTTP/1.1\r\nHost: x\r\nAccept-Encoding: br\r\n\r\n");
  EXPECT_EQ(StatusOf(br), 200) << br.substr(0, 300);
  EXPECT_EQ(br.find("Content-Encoding"), std::string::npos) << br.substr(0, 300);
  const std::string both = Exchange("GET /app.js HTTP/1.1\r\nHost: x\r\nAccept-Encoding: gzip, deflate, br\r\n\r\n");
  EXPECT_EQ(StatusOf(both), 200);
  EXPECT_NE(both.find("Content-Encoding: gzip"), std::string::npos) << both.substr(0, 300);
  const int fd = Connect(port_);
  ASSERT_GE(fd, 0);
  SendAll(fd, "GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " + std::string(kViewerToken) + "\r\n\r\n");
  ::shutdown(fd, SHUT_WR);
  const std::string a = ReadAnswer(fd, 5.0);
  ::close(fd);
  EXPECT_EQ(StatusOf(a), 200) << a.substr(0, 300);
}

// Issue 34 (high): at the total connection cap, connections still waiting for their heads are shed before a
// new one is refused: 600 slow heads from one address (the cap is 512; per address 600 here) leave the page
// answering for everyone else. Before, every other client got 429.
TEST_F(WebDoorTest, SlowHeadsAreShedAtTheTotalCap) {
  server_.reset();
  StartServer(R"(, "max_connections_per_client": 600)");
  std::vector<int> slow;
  for (int k = 0; k < 600; ++k) {
    const int fd = Connect(port_);
    if (fd < 0) break;
    SendAll(fd, "GET /api/benches HTTP/1.1\r\nHost: x\r\n");
    slow.push_back(fd);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  double worst_s = 0;
  for (int k = 0; k < 5; ++k) worst_s = std::max(worst_s, PageAnswers_s());
  std::cout << "page with 600 slow heads (cap 512): answered in " << worst_s * 1000 << " ms (worst of 5)\n";
  RecordProperty("page_ms_with_600_slow_heads", std::to_string(static_cast<int>(worst_s * 1000)));
  EXPECT_LT(worst_s, 1.0);
  for (int fd : slow) ::close(fd);
  ExpectUp();
}

// Issue 34 (high): one address runs at most a quarter of the workers at once; its other requests wait, and a
// body trickled in is not read faster for it. 40 trickled bodies from one address (workers 16, so 4 each here)
// leave the page answering at once for another client... on loopback every client is 127.0.0.1, so the page's
// requests here come from 127.0.0.2.
TEST_F(WebDoorTest, OneAddressRunsAtMostItsShareOfTheWorkers) {
  server_.reset();
  StartServer(R"(, "workers": 16, "max_streams": 8)");
  std::vector<int> trickled;
  for (int k = 0; k < 40; ++k) {
    const int fd = Connect(port_);
    ASSERT_GE(fd, 0);
    SendAll(fd, "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n" + kOperatorAuth +
                    "Content-Length: 100000\r\n\r\n{");
    trickled.push_back(fd);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  // From 127.0.0.2 (another address on loopback).
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in from{};
  from.sin_family = AF_INET;
  from.sin_addr.s_addr = htonl(0x7f000002);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&from), sizeof(from)), 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(static_cast<uint16_t>(port_));
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&to), sizeof(to)), 0);
  const auto t0 = Clock::now();
  SendAll(fd, "GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " + std::string(kViewerToken) + "\r\n\r\n");
  const std::string a = ReadAnswer(fd, 5.0);
  const double s = std::chrono::duration<double>(Clock::now() - t0).count();
  ::close(fd);
  std::cout << "another address's request with 40 trickled bodies from one address (16 workers): " << s * 1000
            << " ms\n";
  EXPECT_EQ(StatusOf(a), 200) << a.substr(0, 300);
  for (int t : trickled) ::close(t);
  ExpectUp();
}

int ConnectFrom(uint32_t from_host, int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  int small = 4096;
  setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &small, sizeof(small));
  sockaddr_in from{};
  from.sin_family = AF_INET;
  from.sin_addr.s_addr = htonl(from_host);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(static_cast<uint16_t>(port));
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&from), sizeof(from)) != 0 ||
      ::connect(fd, reinterpret_cast<sockaddr*>(&to), sizeof(to)) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

// Issue 34 (high): a reader that takes the answer a trickle at a time (1 KiB/s, so each send progresses and the
// socket's 10 s send timeout never fires) lets its worker go within seconds once the buffers are full
// (write_grace_s 5 s, then at least 16 KiB/s of the time the server waits). Four such readers from four
// addresses hold all four workers; the page from a fifth answers once they are cut. Before: ~40 s and more.
TEST_F(WebDoorTest, ATrickleReaderIsCutWithinSeconds) {
  server_.reset();
  StartServer(R"(, "workers": 4, "max_streams": 1)");
  std::vector<int> slow;
  std::string many;
  for (int k = 0; k < 200; ++k) many += "GET /dygraph.min.js HTTP/1.1\r\nHost: x\r\n\r\n";
  for (uint32_t k = 0; k < 4; ++k) {
    const int fd = ConnectFrom(0x7f000002 + k, port_);
    ASSERT_GE(fd, 0);
    SendAll(fd, many);
    slow.push_back(fd);
  }
  std::atomic<bool> stop{false};
  std::thread trickle([&] {
    char buf[1024];
    while (!stop) {
      for (int fd : slow) (void)::recv(fd, buf, sizeof(buf), MSG_DONTWAIT);
      std::this_thread::sleep_for(std::chrono::seconds(1));
    }
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const auto t0 = Clock::now();
  int status = 0;
  while (status != 200 && Clock::now() - t0 < std::chrono::seconds(25)) {
    const int fd = Connect(port_);
    SendAll(fd, "GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer " + std::string(kViewerToken) +
                    "\r\n\r\n");
    status = StatusOf(ReadAnswer(fd, 1.0));
    ::close(fd);
  }
  const double s = std::chrono::duration<double>(Clock::now() - t0).count();
  stop = true;
  trickle.join();
  for (int fd : slow) ::close(fd);
  std::cout << "four trickle readers holding all four workers: page answered after " << s << " s\n";
  RecordProperty("page_s_after_trickle_readers", std::to_string(s));
  EXPECT_EQ(status, 200);
  EXPECT_LT(s, 15.0);
  ExpectUp();
}


// The service's store pool (service/service.h): at most 8 connections kept idle, the rest closed when handed
// back; at most kMaxOpen open, a call beyond waits kAcquireWait_s, then UNAVAILABLE naming the limit.
TEST(ServiceStorePool, KeepsEightIdleAndCapsTheOpen) {
  const std::string dir = ::testing::TempDir() + "/store-pool";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  vb::server::StorePool pool(dir + "/pool.db");
  std::vector<vb::server::StorePool::Handle> held;
  for (int k = 0; k < 20; ++k) {
    auto h = pool.Acquire();
    ASSERT_TRUE(h.ok()) << h.status().message();
    held.push_back(std::move(h.value()));
  }
  EXPECT_EQ(pool.open(), 20);
  held.clear();
  EXPECT_EQ(pool.open(), vb::server::StorePool::kMaxIdle);
  EXPECT_EQ(pool.idle(), vb::server::StorePool::kMaxIdle);
  for (int k = 0; k < vb::server::StorePool::kMaxOpen; ++k) {
    auto h = pool.Acquire();
    ASSERT_TRUE(h.ok()) << h.status().message();
    held.push_back(std::move(h.value()));
  }
  auto beyond = pool.Acquire();
  ASSERT_FALSE(beyond.ok());
  EXPECT_NE(beyond.status().message().find("store: 128 connections in use"), std::string::npos)
      << beyond.status().message();
  held.clear();
  EXPECT_EQ(pool.open(), vb::server::StorePool::kMaxIdle);
  std::filesystem::remove_all(dir);
}

}  // namespace
