#include "catgs/server/encode_methods.hpp"

#include <algorithm>

namespace catgs::server {

// One caller's frame: its parts are claimed in order by whoever is free (the caller first).
// It lives on the caller's stack; helpers touch it only under the mutex or while running a
// part they claimed, and the caller returns only after every part has finished.
struct EncodePool::Batch {
    const std::function<void(int)>* part = nullptr;
    int parts = 0;
    int claimed = 0;
    int finished = 0;
    std::exception_ptr error;
};

EncodePool::EncodePool(int threads) {
    for (int i = 1; i < threads; ++i) helpers_.emplace_back([this] { help(); });
}

EncodePool::~EncodePool() {
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
    }
    wake_.notify_all();
    for (auto& helper : helpers_) helper.join();
}

int EncodePool::claim(Batch& batch) {
    if (batch.claimed == batch.parts) return -1;
    const int index = batch.claimed++;
    if (batch.claimed == batch.parts) batches_.erase(std::find(batches_.begin(), batches_.end(), &batch));
    return index;
}

void EncodePool::finish(Batch& batch, std::exception_ptr error) {
    std::lock_guard lock(mutex_);
    if (error && !batch.error) batch.error = error;
    if (++batch.finished == batch.parts) done_.notify_all();
}

void EncodePool::help() {
    for (;;) {
        Batch* batch = nullptr;
        int index = -1;
        {
            std::unique_lock lock(mutex_);
            wake_.wait(lock, [this] { return stopping_ || !batches_.empty(); });
            if (stopping_) return;  // no batch can be waiting: each caller is inside run()
            batch = batches_.front();
            index = claim(*batch);
        }
        std::exception_ptr error;
        try {
            (*batch->part)(index);
        } catch (...) {
            error = std::current_exception();
        }
        finish(*batch, error);
    }
}

void EncodePool::run(int parts, const std::function<void(int)>& part) {
    if (parts <= 0) return;
    if (parts == 1 || helpers_.empty()) {
        for (int i = 0; i < parts; ++i) part(i);
        return;
    }
    Batch batch;
    batch.part = &part;
    batch.parts = parts;
    {
        std::lock_guard lock(mutex_);
        batches_.push_back(&batch);
    }
    // The caller takes parts too, so waking more helpers than the other parts is waste.
    const int wanted = std::min(parts - 1, static_cast<int>(helpers_.size()));
    for (int i = 0; i < wanted; ++i) wake_.notify_one();
    for (;;) {
        int index;
        {
            std::lock_guard lock(mutex_);
            index = claim(batch);
        }
        if (index < 0) break;
        std::exception_ptr error;
        try {
            part(index);
        } catch (...) {
            error = std::current_exception();
        }
        finish(batch, error);
    }
    std::unique_lock lock(mutex_);
    done_.wait(lock, [&batch] { return batch.finished == batch.parts; });
    if (batch.error) std::rethrow_exception(batch.error);
}

}  // namespace catgs::server
