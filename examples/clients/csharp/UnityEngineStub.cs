// For run-tests.sh only, never for a Unity project (it would clash with the
// real UnityEngine): the few UnityEngine members InbetweenStream.cs uses, with
// Unity's signatures, so that Mono type-checks the MonoBehaviour under
// UNITY_5_3_OR_NEWER. They do nothing.

namespace UnityEngine
{
    public class Object
    {
        public string name { get; set; }
    }

    public class Component : Object
    {
        public Transform transform { get { return null; } }

        public T[] GetComponentsInChildren<T>(bool includeInactive)
        {
            return new T[0];
        }
    }

    public class Behaviour : Component
    {
    }

    public class MonoBehaviour : Behaviour
    {
    }

    public class Transform : Component
    {
        public Vector3 localPosition { get; set; }
        public Quaternion localRotation { get; set; }
        public Vector3 localScale { get; set; }
    }

    public struct Vector3
    {
        public float x, y, z;

        public Vector3(float x, float y, float z)
        {
            this.x = x;
            this.y = y;
            this.z = z;
        }
    }

    public struct Quaternion
    {
        public float x, y, z, w;

        public Quaternion(float x, float y, float z, float w)
        {
            this.x = x;
            this.y = y;
            this.z = z;
            this.w = w;
        }
    }

    public static class Debug
    {
        public static void LogWarning(object message, Object context)
        {
        }
    }

    [System.AttributeUsage(System.AttributeTargets.Field)]
    public class TooltipAttribute : System.Attribute
    {
        public TooltipAttribute(string tooltip)
        {
        }
    }
}
