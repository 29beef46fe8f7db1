// The web endpoint's pure rules (server/src/web_paths.cpp): which file a URL names and which
// it must never name, content types, query parameters, and the gRPC status as a WebSocket
// close code and reason or an HTTP status.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "catgs/server/web_endpoint.hpp"

namespace catgs::test {
namespace {

namespace fs = std::filesystem;
namespace web = server::web;

class WebPathsTest : public ::testing::Test {
protected:
    void SetUp() override {
        base_ = fs::path(CATGS_TEST_TMP) / ("web-paths-" + std::to_string(getpid()));
        fs::remove_all(base_);
        fs::create_directories(base_ / "root" / "assets");
        std::ofstream(base_ / "root" / "index.html") << "<html>viewer</html>";
        std::ofstream(base_ / "root" / "assets" / "app.js") << "console.log(1)";
        std::ofstream(base_ / "root" / ".env") << "SECRET=1";
        std::ofstream(base_ / "secret.txt") << "outside";
        fs::create_symlink(base_ / "secret.txt", base_ / "root" / "escape.txt");
        fs::create_symlink(base_ / "root" / "assets" / "app.js", base_ / "root" / "inside.js");
        root_ = fs::canonical(base_ / "root").string();
    }
    void TearDown() override {
        std::error_code ec;
        fs::remove_all(base_, ec);
    }
    fs::path base_;
    std::string root_;
};

TEST_F(WebPathsTest, FilesUnderTheRootAreFound) {
    EXPECT_EQ(web::resolve_static_path(root_, "/").path, root_ + "/index.html");
    EXPECT_EQ(web::resolve_static_path(root_, "/index.html?token=abc").path, root_ + "/index.html");
    EXPECT_EQ(web::resolve_static_path(root_, "/assets/app.js").path, root_ + "/assets/app.js");
    EXPECT_EQ(web::resolve_static_path(root_, "/assets/%61pp.js").path, root_ + "/assets/app.js");
    // A symlink that stays inside the root is followed.
    EXPECT_EQ(web::resolve_static_path(root_, "/inside.js").path, root_ + "/assets/app.js");
}

TEST_F(WebPathsTest, TraversalAndHiddenFilesAreRefused) {
    struct Case {
        const char* target;
        int status;
        const char* message;
    };
    const Case cases[] = {
        {"/../secret.txt", 400, "'.', '..' and hidden segments"},
        {"/assets/../../secret.txt", 400, "'.', '..' and hidden segments"},
        {"/%2e%2e/secret.txt", 400, "'.', '..' and hidden segments"},
        {"/%2E%2E%2Fsecret.txt", 400, "'.', '..' and hidden segments"},
        {"/./index.html", 400, "'.', '..' and hidden segments"},
        {"//etc/passwd", 400, "empty"},
        {"/.env", 400, "hidden"},
        {"etc/passwd", 400, "must start with '/'"},
        {"/%zz", 400, "malformed %-escape"},
        {"/index.html%00.js", 400, "NUL and backslash"},
        {"/..%5csecret.txt", 400, "NUL and backslash"},
        {"/escape.txt", 404, "outside the web root"},
        {"/missing.js", 404, "no such file"},
        {"/assets", 404, "not a file"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.target);
        const web::StaticPath p = web::resolve_static_path(root_, c.target);
        EXPECT_TRUE(p.path.empty()) << p.path;
        EXPECT_EQ(p.http_status, c.status);
        EXPECT_NE(p.error.find(c.message), std::string::npos) << p.error;
    }
}

TEST(WebRules, ContentTypes) {
    EXPECT_EQ(web::content_type_for("/a/index.html"), "text/html; charset=utf-8");
    EXPECT_EQ(web::content_type_for("app.js"), "text/javascript; charset=utf-8");
    EXPECT_EQ(web::content_type_for("x.css"), "text/css; charset=utf-8");
    EXPECT_EQ(web::content_type_for("shot.png"), "image/png");
    EXPECT_EQ(web::content_type_for("a.wasm"), "application/wasm");
    EXPECT_EQ(web::content_type_for("README"), "application/octet-stream");
}

TEST(WebRules, QueryParameters) {
    EXPECT_EQ(web::query_parameter("/ws/stream?token=a%20b&session=s1", "token"), "a b");
    EXPECT_EQ(web::query_parameter("/ws/stream?token=a%20b&session=s1", "session"), "s1");
    EXPECT_EQ(web::query_parameter("/ws/stream?tokens=x", "token"), std::nullopt);
    EXPECT_EQ(web::query_parameter("/ws/stream", "token"), std::nullopt);
    EXPECT_EQ(web::query_parameter("/ws/stream?token", "token"), "");
    EXPECT_EQ(web::query_parameter("/ws/stream?token=%g1", "token"), std::nullopt);
}

TEST(WebRules, CloseCodesAndHttpStatuses) {
    EXPECT_EQ(web::close_code_for(grpc::StatusCode::OK), 1000);
    EXPECT_EQ(web::close_code_for(grpc::StatusCode::INVALID_ARGUMENT), 4003);
    EXPECT_EQ(web::close_code_for(grpc::StatusCode::DEADLINE_EXCEEDED), 4004);
    EXPECT_EQ(web::close_code_for(grpc::StatusCode::UNAVAILABLE), 4014);
    EXPECT_EQ(web::close_code_for(grpc::StatusCode::UNAUTHENTICATED), 4016);
    EXPECT_EQ(web::http_status_for(grpc::StatusCode::INVALID_ARGUMENT), 400);
    EXPECT_EQ(web::http_status_for(grpc::StatusCode::UNAUTHENTICATED), 401);
    EXPECT_EQ(web::http_status_for(grpc::StatusCode::PERMISSION_DENIED), 403);
    EXPECT_EQ(web::http_status_for(grpc::StatusCode::NOT_FOUND), 404);
    EXPECT_EQ(web::http_status_for(grpc::StatusCode::RESOURCE_EXHAUSTED), 429);
    EXPECT_EQ(web::http_status_for(grpc::StatusCode::UNAVAILABLE), 503);
    EXPECT_EQ(web::http_status_for(grpc::StatusCode::INTERNAL), 500);
}

TEST(WebRules, StatusTextIsCutAtACharacterBoundary) {
    const grpc::Status status(grpc::StatusCode::INVALID_ARGUMENT, "open.scene_id: 'caf\xc3\xa9' unknown");
    EXPECT_EQ(web::status_text(status), "INVALID_ARGUMENT: open.scene_id: 'caf\xc3\xa9' unknown");
    // 'é' is two bytes, at offsets 37 and 38: a cut at 38 must not keep half of it.
    EXPECT_EQ(web::status_text(status, 38), "INVALID_ARGUMENT: open.scene_id: 'caf");
    EXPECT_EQ(web::status_text(status, 39), "INVALID_ARGUMENT: open.scene_id: 'caf\xc3\xa9");
    const std::string long_message(500, 'x');
    EXPECT_EQ(web::status_text({grpc::StatusCode::UNAVAILABLE, long_message}, 123).size(), 123u);
    EXPECT_EQ(web::status_text(grpc::Status::OK), "OK");
}

}  // namespace
}  // namespace catgs::test
