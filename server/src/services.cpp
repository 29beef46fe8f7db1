#include "catgs/server/services.hpp"

#include <spdlog/spdlog.h>

#include <chrono>

#include "catgs/server/frame_messages.hpp"
#include "catgs/server/request_validation.hpp"
#include "catgs/server/stream_session.hpp"
#include "catgs/server/wire.hpp"

namespace catgs::server {
namespace {

using Clock = std::chrono::steady_clock;

grpc::ServerUnaryReactor* finish_now(grpc::CallbackServerContext* context, const grpc::Status& status) {
    grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
    reactor->Finish(status);
    return reactor;
}

/// Bounds on repeated fields, checked before the enum walk visits each of their elements.
grpc::Status check_list_lengths(const google::protobuf::Message&) {
    return grpc::Status::OK;
}
grpc::Status check_list_lengths(const v1::RenderRequest& request) {
    return check_flight_plan_length(request.frame(), "frame");
}

/// A unary request: the bytes parsed (malformed_request when they are not a `Message`) and
/// every enum field checked against its descriptor, whatever the method.
template <typename Message>
grpc::Status parse_request(const grpc::ByteBuffer& in, Message* out) {
    if (!parse_message(in, out)) return malformed_request(Message::descriptor()->name(), in);
    if (grpc::Status s = check_list_lengths(*out); !s.ok()) return s;
    return check_enum_values(*out, "");
}

}  // namespace

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* RenderServiceImpl::Stream(
    grpc::CallbackServerContext* context) {
    auto session = std::make_shared<StreamSession>(core_, context);
    session->start();
    return session.get();  // owned by itself until OnDone
}

grpc::ServerUnaryReactor* RenderServiceImpl::Render(grpc::CallbackServerContext* context,
                                                    const grpc::ByteBuffer* request_bytes, grpc::ByteBuffer* response) {
    if (grpc::Status auth = core_.authorize(context); !auth.ok()) return finish_now(context, auth);
    v1::RenderRequest request;
    if (grpc::Status parsed = parse_request(*request_bytes, &request); !parsed.ok()) return finish_now(context, parsed);
    // Everything one render needs, kept alive until it finishes.
    struct Job {
        SessionSetup setup;
        FrameSetup frame;
        std::unique_ptr<Admission::Ticket> ticket;
        std::unique_ptr<SceneRegistry::Lease> lease;
        std::unique_ptr<DevicePlacement::Seat> seat;  // released before the lease and the ticket
        ImageRGB8 image;
        v1::Frame frame_out;
        Clock::time_point received = Clock::now();
    };
    auto job = std::make_shared<Job>();
    grpc::Status status = parse_session_config(request.config(), core_.options().limits, "config", &job->setup);
    if (status.ok()) status = parse_frame_request(request.frame(), job->setup.intrinsics, "frame", &job->frame);
    if (status.ok()) status = core_.admission().admit(&job->ticket);
    if (status.ok()) status = acquire_scene(core_.scenes(), job->setup.scene_id, "config", &job->lease);
    if (status.ok()) status = core_.placement().place(job->setup.scene_id, &job->seat);
    if (!status.ok()) return finish_now(context, status);
    // One frame: no inter-frame cache to reuse.
    job->setup.options.catgs.cache = CacheMode::off;
    core_.counters().sessions_opened++;

    grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
    ServerCore& core = core_;
    const bool posted = core_.render_pool().post([&core, job, reactor, response] {
        const Clock::time_point begin = Clock::now();
        FrameStats stats;
        const std::uint64_t max_bytes = core.options().limits.max_session_bytes;
        const std::optional<RenderFailure> failure = catch_render_failure([&] {
            // Renderers are pooled across calls and sessions (making one is slow on CUDA).
            auto renderer = core.acquire_renderer(job->lease->scene(), *job->seat);
            stats = renderer->render_rgb8(job->frame.camera, job->setup.options, job->image);
            job->seat->record_render(stats.total_ms);
            // Over the memory limit: the renderer's grow-only arenas are not kept.
            if (max_bytes == 0 || stats.arena_bytes <= max_bytes)
                core.release_renderer(std::move(renderer), job->lease->scene(), *job->seat);
        });
        if (failure) {
            if (failure->out_of_memory) {
                core.counters().out_of_memory++;
                core.drop_idle_renderers(*job->seat);  // so that a retry finds the memory free
            }
            reactor->Finish(render_failure_status(*failure, /*size=*/""));
            return;
        }
        if (max_bytes > 0 && stats.arena_bytes > max_bytes) {
            core.counters().out_of_memory++;
            reactor->Finish(session_memory_status(job->setup.scene_id, /*size=*/"", stats.arena_bytes, max_bytes));
            return;
        }
        job->frame_out = rendered_frame(job->frame, job->setup.encode.format, job->image, stats,
                                        {job->received, begin, Clock::now()});
        const bool encoding = core.encode_pool().post([job, reactor, response] {
            v1::Frame& out = job->frame_out;
            if (grpc::Status encoded = encode_frame(job->image, job->setup.encode, job->received, out); !encoded.ok()) {
                reactor->Finish(encoded);
                return;
            }
            out.mutable_stats()->set_frames_sent(1);
            serialize_message(out, response);
            reactor->Finish(grpc::Status::OK);
        });
        if (!encoding)
            reactor->Finish(shutting_down_status());
        else
            core.counters().frames_sent++;
    });
    if (!posted) reactor->Finish(shutting_down_status());
    return reactor;
}

void SceneServiceImpl::fill(const SceneSummary& s, v1::SceneInfo* info) const {
    info->set_scene_id(s.id);
    info->set_source(s.source);
    info->set_gaussian_count(s.gaussians);
    info->set_sh_degree(s.sh_degree);
    auto* min = info->mutable_bounds()->mutable_min();
    auto* max = info->mutable_bounds()->mutable_max();
    min->set_x(s.bounds.min[0]);
    min->set_y(s.bounds.min[1]);
    min->set_z(s.bounds.min[2]);
    max->set_x(s.bounds.max[0]);
    max->set_y(s.bounds.max[1]);
    max->set_z(s.bounds.max[2]);
    info->set_host_bytes(s.host_bytes);
    const std::vector<DevicePlacement::SceneOnDevice> where = core_.placement().residency(s.id);
    for (const DevicePlacement::SceneOnDevice& d : where) {
        v1::SceneDevice* out = info->add_devices();
        out->set_device(d.device);
        out->set_sessions(static_cast<std::uint32_t>(d.sessions));
        out->set_pooled_renderers(static_cast<std::uint32_t>(d.pooled_renderers));
        out->set_render_load(d.load);
    }
    // The sessions of one device share one copy of a scene there (renderer_factory.cpp,
    // shared_device_scene); the CPU backend's simulated devices share the host's.
    info->set_device_bytes(core_.options().backend == "cuda" ? s.host_bytes * where.size() : 0);
    info->set_sessions(s.sessions);
    info->set_state(s.unloading ? v1::SCENE_STATE_UNLOADING : v1::SCENE_STATE_READY);
}

grpc::ServerUnaryReactor* SceneServiceImpl::LoadScene(grpc::CallbackServerContext* context,
                                                      const grpc::ByteBuffer* request_bytes,
                                                      grpc::ByteBuffer* response) {
    if (grpc::Status auth = core_.authorize(context); !auth.ok()) return finish_now(context, auth);
    auto request = std::make_shared<v1::LoadSceneRequest>();
    if (grpc::Status parsed = parse_request(*request_bytes, request.get()); !parsed.ok())
        return finish_now(context, parsed);
    if (core_.admission().draining()) return finish_now(context, shutting_down_status());
    grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
    // Loading reads and validates a whole file (seconds for big scenes): off the gRPC threads.
    const bool posted = core_.admin_pool().post([this, request, response, reactor] {
        SceneSummary summary;
        grpc::Status status =
            core_.scenes().load(request->scene_id(), request->source(), request->drop_invalid(), false, &summary);
        if (status.ok()) {
            v1::SceneInfo info;
            fill(summary, &info);
            serialize_message(info, response);
        } else if (status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED) {
            core_.counters().out_of_memory++;
            spdlog::warn("LoadScene '{}' refused: {}", request->source(), status.error_message());
        }
        reactor->Finish(status);
    });
    if (!posted) reactor->Finish(shutting_down_status());
    return reactor;
}

grpc::ServerUnaryReactor* SceneServiceImpl::ListScenes(grpc::CallbackServerContext* context,
                                                       const grpc::ByteBuffer* request_bytes,
                                                       grpc::ByteBuffer* response) {
    if (grpc::Status auth = core_.authorize(context); !auth.ok()) return finish_now(context, auth);
    v1::ListScenesRequest request;
    if (grpc::Status parsed = parse_request(*request_bytes, &request); !parsed.ok()) return finish_now(context, parsed);
    v1::ListScenesResponse list;
    for (const SceneSummary& s : core_.scenes().list()) fill(s, list.add_scenes());
    serialize_message(list, response);
    return finish_now(context, grpc::Status::OK);
}

grpc::ServerUnaryReactor* SceneServiceImpl::UnloadScene(grpc::CallbackServerContext* context,
                                                        const grpc::ByteBuffer* request_bytes,
                                                        grpc::ByteBuffer* response) {
    if (grpc::Status auth = core_.authorize(context); !auth.ok()) return finish_now(context, auth);
    v1::UnloadSceneRequest request;
    if (grpc::Status parsed = parse_request(*request_bytes, &request); !parsed.ok()) return finish_now(context, parsed);
    SceneSummary summary;
    bool freed = false;
    grpc::Status status = core_.scenes().unload(request.scene_id(), &summary, &freed);
    if (status.ok()) {
        v1::UnloadSceneResponse out;
        fill(summary, out.mutable_scene());
        out.set_freed(freed);
        serialize_message(out, response);
    }
    return finish_now(context, status);
}

grpc::ServerUnaryReactor* SceneServiceImpl::GetScene(grpc::CallbackServerContext* context,
                                                     const grpc::ByteBuffer* request_bytes,
                                                     grpc::ByteBuffer* response) {
    if (grpc::Status auth = core_.authorize(context); !auth.ok()) return finish_now(context, auth);
    v1::GetSceneRequest request;
    if (grpc::Status parsed = parse_request(*request_bytes, &request); !parsed.ok()) return finish_now(context, parsed);
    SceneSummary summary;
    grpc::Status status = core_.scenes().get(request.scene_id(), &summary);
    if (status.ok()) {
        v1::SceneInfo info;
        fill(summary, &info);
        serialize_message(info, response);
    }
    return finish_now(context, status);
}

}  // namespace catgs::server
