// SPDX-License-Identifier: Apache-2.0
#include "renderer/scene/scene.h"

#include <algorithm>
#include <cmath>

#include <glm/gtc/matrix_transform.hpp>

namespace texcache {

glm::mat4 TransformTrack::Eval(float time) const {
    if (keys.empty()) return glm::mat4(1.0f);
    const Keyframe* a = &keys.front();
    const Keyframe* b = a;
    float f = 0.0f;
    // Written so a NaN time takes the first key instead of running off the end.
    if (!(time > keys.front().time)) {
        a = b = &keys.front();
    } else if (!(time < keys.back().time)) {
        a = b = &keys.back();
    } else {
        const auto it = std::upper_bound(keys.begin(), keys.end(), time,
                                         [](float t, const Keyframe& k) { return t < k.time; });
        b = &*it;
        a = &*(it - 1);
        f = (time - a->time) / (b->time - a->time);
    }
    const glm::vec3 t = glm::mix(a->translation, b->translation, f);
    // Shortest path: q and -q are the same rotation, take the one on a's side.
    const glm::quat r = glm::slerp(
        a->rotation, glm::dot(a->rotation, b->rotation) < 0.0f ? -b->rotation : b->rotation, f);
    const glm::vec3 s = glm::mix(a->scale, b->scale, f);
    return glm::translate(glm::mat4(1.0f), t) * glm::mat4_cast(r) * glm::scale(glm::mat4(1.0f), s);
}

bool TransformTrack::IsAnimated() const {
    // Every key against the first: any difference means the pose changes somewhere.
    for (size_t i = 1; i < keys.size(); ++i) {
        const Keyframe& a = keys[0];
        const Keyframe& b = keys[i];
        if (a.translation != b.translation || a.scale != b.scale ||
            std::abs(std::abs(glm::dot(a.rotation, b.rotation)) - 1.0f) > 1e-7f)
            return true;
    }
    return false;
}

bool Scene::MovesBetween(float a, float b) const {
    for (const Object& o : objects)
        if (o.transform.MovesBetween(a, b)) return true;
    for (const QuadLight& l : quadLights)
        if (l.transform.MovesBetween(a, b)) return true;
    for (const DistantLight& l : distantLights)
        if (l.transform.MovesBetween(a, b)) return true;
    for (const PointLight& l : pointLights)
        if (l.transform.MovesBetween(a, b)) return true;
    return false;
}

std::vector<int> Object::Materials() const {
    std::vector<int> ids{material};
    for (const int m : faceMaterials)
        if (std::find(ids.begin(), ids.end(), m) == ids.end()) ids.push_back(m);
    return ids;
}

}  // namespace texcache
