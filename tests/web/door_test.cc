// The web door (web/door.h, docs/web.md "Door" and "Limits") against the real valvebench-server on loopback,
// with raw sockets so that the requests are sent byte for byte as an attacker would: every request of issue 24
// gets a 4xx JSON answer and the server stays up (a crash is a failure: the next request finds no server), heads
// and bodies are bounded whatever the framing, slow clients and many live views leave the page answering.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <httplib.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "tests/integration/server_process.h"
#include "web/gateway.h"

namespace {

using Json = nlohmann::json;
using Clock = std::chrono::steady_clock;
using vb::testing::kOperatorToken;
using vb::testing::kViewerToken;

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
       "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: " +
           std::to_string(deep_body.size()) + "\r\n\r\n" + deep_body,
       400, "nested deeper than 64"},
      {"invalid UTF-8 in a body",
       "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: " +
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
    SendAll(fd, "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n");
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
  SendAll(fd, "POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: 1000\r\n\r\n{");
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

}  // namespace
