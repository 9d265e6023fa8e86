// The dashboard's sessions kept over a restart (web/session_store.h, issue 39 point 4).
#include "web/session_store.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

namespace {

std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string FreshPath(const std::string& name) {
  const std::string dir = ::testing::TempDir() + "/session-store-" + name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir + "/web-sessions";
}

double g_now_s = 1.0e9;
double FakeNow() { return g_now_s; }

TEST(SessionStore, ASessionOpensAfterAReloadAndTheFileHoldsNeitherTokenNorId) {
  const std::string path = FreshPath("reload");
  std::string id;
  {
    vb::web::SessionStore store(path);
    id = store.Create("tok-Operator.1", "olga");
    EXPECT_EQ(store.TokenOf(id), "tok-Operator.1");
  }
  const std::string text = Slurp(path);
  EXPECT_EQ(text.find("tok-Operator.1"), std::string::npos);
  EXPECT_EQ(text.find(id), std::string::npos);
  EXPECT_NE(text.find("\"olga\""), std::string::npos);
  EXPECT_EQ(std::filesystem::status(path).permissions() & std::filesystem::perms::others_read,
            std::filesystem::perms::none);
  vb::web::SessionStore again(path);
  EXPECT_EQ(again.Size(), 1u);
  EXPECT_EQ(again.TokenOf(id), "tok-Operator.1");
  std::string other = id;
  other[0] = other[0] == 'a' ? 'b' : 'a';
  EXPECT_EQ(again.TokenOf(other), "");
  EXPECT_TRUE(again.Revoke(id));
  EXPECT_FALSE(again.Revoke(id));
  EXPECT_EQ(vb::web::SessionStore(path).TokenOf(id), "");
}

// An altered record does not open (AES-GCM's tag), and the id hash is bound as associated data, so a sealed
// token moved onto another record's id does not open either.
TEST(SessionStore, AnAlteredOrMovedRecordDoesNotOpen) {
  const std::string path = FreshPath("altered");
  std::string a, b;
  {
    vb::web::SessionStore store(path);
    a = store.Create("token-a", "ann");
    b = store.Create("token-b", "bob");
  }
  std::string text = Slurp(path);
  // Swap the two sealed values.
  auto sealed_at = [&](std::size_t from) {
    const auto k = text.find("\"sealed\": \"", from);
    return std::make_pair(k + 11, text.find('"', k + 11));
  };
  auto [s1, e1] = sealed_at(0);
  auto [s2, e2] = sealed_at(e1);
  const std::string v1 = text.substr(s1, e1 - s1), v2 = text.substr(s2, e2 - s2);
  text = text.substr(0, s1) + v2 + text.substr(e1, s2 - e1) + v1 + text.substr(e2);
  std::ofstream(path, std::ios::binary | std::ios::trunc) << text;
  vb::web::SessionStore store(path);
  EXPECT_EQ(store.Size(), 2u);
  EXPECT_EQ(store.TokenOf(a), "");
  EXPECT_EQ(store.TokenOf(b), "");
}

TEST(SessionStore, SessionsExpireAcrossARestartAndATokenKeepsItsNewest32) {
  const std::string path = FreshPath("expire");
  g_now_s = 1.0e9;
  std::vector<std::string> ids;
  std::string other;
  {
    vb::web::SessionStore store(path, 3600.0);
    store.SetClockForTest(&FakeNow);
    for (int k = 0; k < 40; ++k) {
      ids.push_back(store.Create("one-token", "u"));
      g_now_s += 1.0;
    }
    other = store.Create("another-token", "v");
    EXPECT_EQ(store.Size(), 33u);  // 32 of the first token, one of the other: the other's was not evicted
    EXPECT_EQ(store.TokenOf(ids[7]), "");
    EXPECT_EQ(store.TokenOf(ids[8]), "one-token");
    EXPECT_EQ(store.RevokeAllOf(ids[39]), 32u);
    EXPECT_EQ(store.TokenOf(other), "another-token");
  }
  g_now_s += 3600.0;  // past the other's end
  vb::web::SessionStore later(path, 3600.0);
  later.SetClockForTest(&FakeNow);
  EXPECT_EQ(later.TokenOf(other), "");
  EXPECT_EQ(later.Size(), 0u);
}

TEST(SessionStore, AnUnreadableFileIsMovedAsideAndTheStoreStartsEmpty) {
  const std::string path = FreshPath("unreadable");
  for (const char* bad : {"{not json", R"({"version": 2, "sessions": []})",
                          R"({"version": 1, "sessions": [{"id_sha256": "xyz"}]})"}) {
    std::ofstream(path, std::ios::binary | std::ios::trunc) << bad;
    std::filesystem::remove(path + ".unreadable");
    vb::web::SessionStore store(path);
    EXPECT_EQ(store.Size(), 0u) << bad;
    EXPECT_TRUE(std::filesystem::exists(path + ".unreadable")) << bad;
    EXPECT_EQ(Slurp(path + ".unreadable"), bad);
    const std::string id = store.Create("t", "u");
    EXPECT_EQ(vb::web::SessionStore(path).TokenOf(id), "t") << bad;
  }
}

TEST(SessionStore, InMemoryWithoutAPath) {
  vb::web::SessionStore store;
  const std::string id = store.Create("t", "u");
  std::set<std::string> ids{id};
  for (int k = 0; k < 5; ++k) ids.insert(store.Create("t", "u"));
  EXPECT_EQ(ids.size(), 6u);  // random ids
  EXPECT_EQ(store.TokenOf(id), "t");
}

}  // namespace
