#include "catgs/server/services.hpp"

#include <spdlog/spdlog.h>

#include <chrono>

#include "catgs/server/encoder.hpp"
#include "catgs/server/stream_session.hpp"

namespace catgs::server {
namespace {

using Clock = std::chrono::steady_clock;

double ms_between(Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
}

grpc::ServerUnaryReactor* finish_now(grpc::CallbackServerContext* context, const grpc::Status& status) {
    grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
    reactor->Finish(status);
    return reactor;
}

const grpc::Status kDraining{grpc::StatusCode::UNAVAILABLE, "server is shutting down: reconnect to another instance"};

}  // namespace

grpc::ServerBidiReactor<v1::StreamRequest, v1::Frame>* RenderServiceImpl::Stream(grpc::CallbackServerContext* context) {
    auto session = std::make_shared<StreamSession>(core_, context);
    session->start();
    return session.get();  // owned by itself until OnDone
}

grpc::ServerUnaryReactor* RenderServiceImpl::Render(grpc::CallbackServerContext* context,
                                                    const v1::RenderRequest* request, v1::Frame* response) {
    if (grpc::Status auth = core_.authorize(context); !auth.ok()) return finish_now(context, auth);
    // Everything one render needs, kept alive until it finishes.
    struct Job {
        SessionSetup setup;
        FrameSetup frame;
        std::unique_ptr<Admission::Ticket> ticket;
        std::unique_ptr<SceneRegistry::Lease> lease;
        ImageRGB8 image;
        Clock::time_point received = Clock::now();
    };
    auto job = std::make_shared<Job>();
    grpc::Status status = parse_session_config(request->config(), core_.options().limits, "config", &job->setup);
    if (status.ok()) status = parse_frame_request(request->frame(), job->setup.intrinsics, "frame", &job->frame);
    if (status.ok()) status = core_.admission().admit(&job->ticket);
    if (status.ok()) status = acquire_scene(core_.scenes(), job->setup.scene_id, "config", &job->lease);
    if (!status.ok()) return finish_now(context, status);
    // One frame: no inter-frame cache to reuse.
    job->setup.options.catgs.cache = CacheMode::off;
    core_.counters().sessions_opened++;

    grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
    ServerCore& core = core_;
    const bool posted = core_.render_pool().post([&core, job, reactor, response] {
        const Clock::time_point begin = Clock::now();
        FrameStats stats;
        try {
            auto renderer = core.make_session_renderer();
            renderer->set_scene(job->lease->scene());
            stats = renderer->render_rgb8(job->frame.camera, job->setup.options, job->image);
        } catch (const std::exception& e) {
            reactor->Finish({grpc::StatusCode::INTERNAL, std::string("render failed: ") + e.what()});
            return;
        }
        const Clock::time_point rendered = Clock::now();
        response->set_sequence(job->frame.sequence);
        response->set_encoding(to_proto(job->setup.encode.format));
        response->set_width(static_cast<std::uint32_t>(job->image.width));
        response->set_height(static_cast<std::uint32_t>(job->image.height));
        response->set_client_timestamp_us(job->frame.client_timestamp_us);
        response->mutable_timings()->set_queue_ms(ms_between(job->received, begin));
        response->mutable_timings()->set_render_ms(ms_between(begin, rendered));
        auto* cache = response->mutable_cache();
        cache->set_key_frame(stats.key_frame);
        cache->set_window(static_cast<std::uint32_t>(stats.window));
        cache->set_render_length(stats.pairs);
        cache->set_visible(stats.visible);
        cache->set_split_k(stats.split_k);
        const bool encoding = core.encode_pool().post([job, reactor, response] {
            const Clock::time_point start = Clock::now();
            try {
                encode_image(job->image, job->setup.encode, *response->mutable_data());
            } catch (const std::exception& e) {
                reactor->Finish({grpc::StatusCode::INTERNAL, std::string("encoding failed: ") + e.what()});
                return;
            }
            const Clock::time_point done = Clock::now();
            response->mutable_timings()->set_encode_ms(ms_between(start, done));
            response->mutable_timings()->set_total_ms(ms_between(job->received, done));
            response->mutable_stats()->set_frames_sent(1);
            reactor->Finish(grpc::Status::OK);
        });
        if (!encoding) reactor->Finish(kDraining);
        else core.counters().frames_sent++;
    });
    if (!posted) reactor->Finish(kDraining);
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
    // Sessions share one device copy of a scene (renderer_factory.cpp, shared_device_scene).
    info->set_device_bytes(core_.options().backend == "cuda" && s.sessions > 0 ? s.host_bytes : 0);
    info->set_sessions(s.sessions);
    info->set_state(s.unloading ? v1::SCENE_STATE_UNLOADING : v1::SCENE_STATE_READY);
}

grpc::ServerUnaryReactor* SceneServiceImpl::LoadScene(grpc::CallbackServerContext* context,
                                                      const v1::LoadSceneRequest* request, v1::SceneInfo* response) {
    if (grpc::Status auth = core_.authorize(context); !auth.ok()) return finish_now(context, auth);
    if (core_.admission().draining()) return finish_now(context, kDraining);
    grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
    // Loading reads and validates a whole file (seconds for big scenes): off the gRPC threads.
    const bool posted = core_.admin_pool().post([this, request, response, reactor] {
        SceneSummary summary;
        grpc::Status status =
            core_.scenes().load(request->scene_id(), request->source(), request->drop_invalid(), false, &summary);
        if (status.ok()) fill(summary, response);
        reactor->Finish(status);
    });
    if (!posted) reactor->Finish(kDraining);
    return reactor;
}

grpc::ServerUnaryReactor* SceneServiceImpl::ListScenes(grpc::CallbackServerContext* context,
                                                       const v1::ListScenesRequest*, v1::ListScenesResponse* response) {
    if (grpc::Status auth = core_.authorize(context); !auth.ok()) return finish_now(context, auth);
    for (const SceneSummary& s : core_.scenes().list()) fill(s, response->add_scenes());
    return finish_now(context, grpc::Status::OK);
}

grpc::ServerUnaryReactor* SceneServiceImpl::UnloadScene(grpc::CallbackServerContext* context,
                                                        const v1::UnloadSceneRequest* request,
                                                        v1::UnloadSceneResponse* response) {
    if (grpc::Status auth = core_.authorize(context); !auth.ok()) return finish_now(context, auth);
    SceneSummary summary;
    bool freed = false;
    grpc::Status status = core_.scenes().unload(request->scene_id(), &summary, &freed);
    if (status.ok()) {
        fill(summary, response->mutable_scene());
        response->set_freed(freed);
    }
    return finish_now(context, status);
}

grpc::ServerUnaryReactor* SceneServiceImpl::GetScene(grpc::CallbackServerContext* context,
                                                     const v1::GetSceneRequest* request, v1::SceneInfo* response) {
    if (grpc::Status auth = core_.authorize(context); !auth.ok()) return finish_now(context, auth);
    SceneSummary summary;
    grpc::Status status = core_.scenes().get(request->scene_id(), &summary);
    if (status.ok()) fill(summary, response);
    return finish_now(context, status);
}

}  // namespace catgs::server
