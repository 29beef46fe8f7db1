// catgs-client scenes: the SceneService calls (list, get, load, unload), as a table or JSON.
#include <chrono>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>

#include "catgs/common/exit_codes.hpp"
#include "catgs/error.hpp"
#include "commands.hpp"
#include "exit_status.hpp"

namespace catgs::client {
namespace {

nlohmann::json scene_json(const v1::SceneInfo& s) {
    return {{"scene_id", s.scene_id()},
            {"source", s.source()},
            {"gaussians", s.gaussian_count()},
            {"sh_degree", s.sh_degree()},
            {"bounds_min", {s.bounds().min().x(), s.bounds().min().y(), s.bounds().min().z()}},
            {"bounds_max", {s.bounds().max().x(), s.bounds().max().y(), s.bounds().max().z()}},
            {"host_bytes", s.host_bytes()},
            {"device_bytes", s.device_bytes()},
            {"sessions", s.sessions()},
            {"state", s.state() == v1::SCENE_STATE_UNLOADING ? "unloading" : "ready"}};
}

void print_scene(const v1::SceneInfo& s) {
    std::printf("%-16s %10llu Gaussians  SH %d  %8.1f MB  %u sessions  %-9s  %s\n", s.scene_id().c_str(),
                static_cast<unsigned long long>(s.gaussian_count()), s.sh_degree(), s.host_bytes() / 1e6, s.sessions(),
                s.state() == v1::SCENE_STATE_UNLOADING ? "unloading" : "ready", s.source().c_str());
}

}  // namespace

CLI::App* add_scenes_command(CLI::App& app, ScenesArgs& args) {
    CLI::App* scenes = app.add_subcommand("scenes", "list | get ID | load SOURCE [--id ID] | unload ID");
    scenes->add_option("action", args.action, "list, get, load or unload")->required();
    scenes->add_option("argument", args.argument, "scene id, or the source to load");
    scenes->add_option("--id", args.id, "id for a loaded scene (default: derived from the source)");
    scenes->add_flag("--drop-invalid", args.drop_invalid, "drop invalid records when loading");
    scenes->add_flag("--json", args.json, "machine-readable output");
    return scenes;
}

int run_scenes_command(const Connection& conn, const ScenesArgs& args) {
    const std::string& action = args.action;
    const std::string& arg = args.argument;
    const bool json = args.json;
    auto stub = v1::SceneService::NewStub(conn.channel());
    grpc::ClientContext context;
    conn.add_metadata(context, conn.authorization());
    context.set_wait_for_ready(true);
    // Loading a large scene takes a while; the rest is immediate.
    context.set_deadline(std::chrono::system_clock::now() +
                         (action == "load" ? std::chrono::seconds(600) : kConnectTimeout));
    grpc::Status status;
    nlohmann::json out;
    if (action == "list") {
        v1::ListScenesResponse response;
        status = stub->ListScenes(&context, {}, &response);
        out = nlohmann::json::array();
        for (const auto& s : response.scenes()) {
            if (json)
                out.push_back(scene_json(s));
            else
                print_scene(s);
        }
    } else if (action == "get" || action == "load" || action == "unload") {
        if (arg.empty()) throw Error("scenes " + action + ": missing " + (action == "load" ? "SOURCE" : "ID"));
        if (action == "get") {
            v1::GetSceneRequest request;
            request.set_scene_id(arg);
            v1::SceneInfo info;
            status = stub->GetScene(&context, request, &info);
            if (status.ok()) json ? void(out = scene_json(info)) : print_scene(info);
        } else if (action == "load") {
            v1::LoadSceneRequest request;
            request.set_source(arg);
            request.set_scene_id(args.id);
            request.set_drop_invalid(args.drop_invalid);
            v1::SceneInfo info;
            if (!json) std::fprintf(stderr, "loading %s ...\n", arg.c_str());
            status = stub->LoadScene(&context, request, &info);
            if (status.ok()) json ? void(out = scene_json(info)) : print_scene(info);
        } else {
            v1::UnloadSceneRequest request;
            request.set_scene_id(arg);
            v1::UnloadSceneResponse response;
            status = stub->UnloadScene(&context, request, &response);
            if (status.ok()) {
                if (json)
                    out = {{"scene", scene_json(response.scene())}, {"freed", response.freed()}};
                else
                    std::printf("%s: %s\n", arg.c_str(),
                                response.freed() ? "freed" : "unloading (freed when its sessions close)");
            }
        }
    } else {
        throw Error("scenes: unknown action '" + action + "' (expected list, get, load or unload)");
    }
    if (!status.ok()) {
        return report_failure("scenes " + action, status);
    }
    if (json) std::cout << out.dump(2) << "\n";
    return kExitOk;
}

}  // namespace catgs::client
